//! The studio's API against the real binary on a tiny trained run: the
//! token and the Host check, bad requests answered 4xx with one line and
//! nothing changed, 50 requests at once, an edit regenerated and kept (a
//! variant folder that reads back and differs where it was edited), a job
//! cancelled, the run folder's lock, and SIGTERM. The page itself is driven
//! by a real browser in `make studio-test`.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{json, Value};

use crate::common::{shapeshifter, stderr, tiny_trained_run};

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            copy_dir(&p, &to.join(e.file_name()));
        } else {
            std::fs::copy(&p, to.join(e.file_name())).unwrap();
        }
    }
}

/// A studio on a copy of the tiny run: the process, its base address and token.
struct Studio {
    child: Child,
    base: String,
    token: String,
    run: PathBuf,
    _dir: tempfile::TempDir,
}

impl Studio {
    fn start() -> Studio {
        Studio::start_with_files(None)
    }

    /// A studio that may open at most `files` file descriptors (its
    /// RLIMIT_NOFILE), where given.
    fn start_with_files(files: Option<u64>) -> Studio {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path().join("run");
        copy_dir(tiny_trained_run(), &run);
        Studio::launch(run, dir, files)
    }

    /// A studio on `run` (inside `dir`, kept as long as the studio).
    fn launch(run: PathBuf, dir: tempfile::TempDir, files: Option<u64>) -> Studio {
        let mut command = Command::new(env!("CARGO_BIN_EXE_shapeshifter"));
        command.args(["studio", run.to_str().unwrap(), "--port", "0"]).stdout(Stdio::piped()).stderr(Stdio::null());
        if let Some(n) = files {
            use std::os::unix::process::CommandExt;
            // SAFETY: setrlimit is async-signal-safe; nothing else runs between fork and exec.
            unsafe {
                command.pre_exec(move || {
                    let limit = libc::rlimit { rlim_cur: n, rlim_max: n };
                    if libc::setrlimit(libc::RLIMIT_NOFILE, &limit) != 0 {
                        return Err(std::io::Error::last_os_error());
                    }
                    Ok(())
                });
            }
        }
        let mut child = command.spawn().unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
        let url = line.trim().strip_prefix("studio: ").unwrap_or_else(|| panic!("no address printed: {line}")).to_string();
        let (base, token) = url.split_once("/?token=").unwrap();
        let s = Studio { child, base: base.to_string(), token: token.to_string(), run, _dir: dir };
        // The networks load on the worker; the page says when.
        let t = Instant::now();
        while !s.get("/api/state").1["ready"].as_bool().unwrap_or(false) {
            assert!(t.elapsed() < Duration::from_secs(60), "the networks never loaded");
            std::thread::sleep(Duration::from_millis(50));
        }
        s
    }

    fn request(&self, method: &str, path: &str, body: Option<&str>, headers: &[(&str, &str)]) -> (u16, Vec<u8>) {
        crate::common::http::request(&self.base, method, path, body.map(|b| ("application/json", b.as_bytes())), headers)
    }

    fn call(&self, method: &str, path: &str, body: Option<&str>) -> (u16, Value) {
        let (status, bytes) = self.request(method, path, body, &[("X-Studio-Token", &self.token)]);
        (status, serde_json::from_slice(&bytes).unwrap_or(Value::Null))
    }
    fn get(&self, path: &str) -> (u16, Value) {
        self.call("GET", path, None)
    }
    fn post(&self, path: &str, body: Value) -> (u16, Value) {
        self.call("POST", path, Some(&body.to_string()))
    }

    /// Waits for job `id` to finish; its status.
    fn finish(&self, id: &str) -> Value {
        let t = Instant::now();
        loop {
            let (_, j) = self.get(&format!("/api/jobs/{id}"));
            if ["done", "failed", "cancelled"].contains(&j["state"].as_str().unwrap_or("")) {
                return j;
            }
            assert!(t.elapsed() < Duration::from_secs(300), "job {id} never finished: {j}");
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Sends `sig`; the exit status, within `within`.
    fn signal(mut self, sig: i32, within: Duration) -> (Option<i32>, Duration, PathBuf, tempfile::TempDir) {
        // SAFETY: kill(2) on the child this test started and has not reaped.
        unsafe { libc::kill(self.child.id() as i32, sig) };
        let t = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                return (status.code(), t.elapsed(), self.run.clone(), std::mem::replace(&mut self._dir, tempfile::tempdir().unwrap()));
            }
            if t.elapsed() > within {
                let _ = self.child.kill();
                panic!("the studio did not end within {within:?} of signal {sig}");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Studio {
    /// Whether the studio's process still runs (not ended, not a zombie).
    fn child_alive(&self) -> bool {
        std::fs::read_to_string(format!("/proc/{}/stat", self.child.id()))
            .is_ok_and(|stat| stat.rsplit_once(')').and_then(|(_, rest)| rest.split_whitespace().next()).is_some_and(|state| state != "Z"))
    }
}

impl Drop for Studio {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn error_line(v: &Value) -> String {
    let e = v["error"].as_str().unwrap_or_else(|| panic!("no error message: {v}")).to_string();
    assert!(!e.contains('\n') && !e.is_empty(), "{e}");
    e
}

/// Voxels of a level file.
fn voxels(path: &Path) -> usize {
    shapeshifter::io::vdb::read_level(path).unwrap().0.len()
}

#[test]
fn the_studio_answers_only_its_token_and_loopback_and_refuses_bad_requests_with_one_line() {
    let s = Studio::start();
    let state_path = "/api/state";
    // No token, a wrong one: 403. The token as the page gets it (a query,
    // then a cookie) and as a header: 200.
    assert_eq!(s.request("GET", state_path, None, &[]).0, 403);
    assert_eq!(s.request("GET", state_path, None, &[("X-Studio-Token", "0123")]).0, 403);
    assert_eq!(s.request("GET", &format!("{state_path}?token={}", s.token), None, &[]).0, 200);
    let (status, page) = s.request("GET", &format!("/?token={}", s.token), None, &[]);
    assert_eq!(status, 200);
    assert!(String::from_utf8_lossy(&page).contains("/assets/studio.js"));
    let port = s.base.rsplit(':').next().unwrap();
    let cookie = format!("shapeshifter_studio_{port}={}", s.token);
    assert_eq!(s.request("GET", "/assets/three.module.js", None, &[("Cookie", &cookie)]).0, 200);
    // DNS rebinding: another name for 127.0.0.1 is refused, token or not.
    let (status, body) = s.request("GET", state_path, None, &[("X-Studio-Token", &s.token), ("Host", "attacker.example")]);
    assert_eq!(status, 403, "{}", String::from_utf8_lossy(&body));
    // What another site's page could send without asking: a POST as
    // text/plain or a form, or one from another Origin; 403, nothing made.
    let new_draft = r#"{"source": "variant_000", "level": 1}"#;
    for (content_type, origin) in [
        ("text/plain", None),
        ("application/x-www-form-urlencoded", None),
        ("application/json", Some("http://attacker.example")),
        ("application/json", Some("http://127.0.0.1:1")),
        ("application/json", Some("null")),
    ] {
        let mut headers = vec![("X-Studio-Token", s.token.as_str())];
        if let Some(o) = origin {
            headers.push(("Origin", o));
        }
        let (status, body) = crate::common::http::request(&s.base, "POST", "/api/drafts", Some((content_type, new_draft.as_bytes())), &headers);
        assert_eq!(status, 403, "{content_type} from {origin:?}: {}", String::from_utf8_lossy(&body));
    }
    assert_eq!(s.get(state_path).1["drafts"], json!([]), "a refused POST made a draft");
    // From the page's own origin the request reaches its route (which finds
    // no such variant: 404, not 403).
    let own = format!("http://127.0.0.1:{port}");
    let missing = r#"{"source": "variant_042", "level": 1}"#;
    let (status, body) = crate::common::http::request(&s.base, "POST", "/api/drafts", Some(("application/json; charset=utf-8", missing.as_bytes())), &[("X-Studio-Token", &s.token), ("Origin", &own)]);
    assert_eq!(status, 404, "{}", String::from_utf8_lossy(&body));
    // The page holds no token, and no script runs but the studio's own files.
    assert!(!String::from_utf8_lossy(&page).contains(&s.token), "the token is in the page");
    let policy = crate::common::http::response_header(&s.base, &format!("/?token={}", s.token), "Content-Security-Policy").unwrap_or_default();
    assert!(policy.contains("default-src 'none'") && policy.contains("script-src 'self' 'sha256-") && !policy.contains("unsafe"), "{policy}");
    // Nothing served by path: traversal finds no route.
    for p in ["/assets/../config.toml", "/api/shapes/..%2fconfig.toml/preview.png", "/config.toml"] {
        let (status, v) = s.get(p);
        assert!(status == 404, "{p}: {status} {v}");
    }

    let (_, state) = s.get(state_path);
    let ids: Vec<&str> = state["shapes"].as_array().unwrap().iter().map(|v| v["id"].as_str().unwrap()).collect();
    assert_eq!(ids, ["exemplar", "variant_000", "variant_001"]);
    assert_eq!(state["resolutions"], json!([16, 32, 64]));

    // Bad requests: a 4xx with one line, nothing changed.
    let (status, v) = s.call("POST", "/api/drafts", Some("{not json"));
    assert_eq!(status, 400);
    assert!(error_line(&v).contains("malformed request"));
    let (status, v) = s.post("/api/drafts", json!({"source": "variant_042", "level": 1}));
    assert_eq!(status, 404);
    assert!(error_line(&v).contains("variant_042"));
    let (status, v) = s.post("/api/jobs", json!({"kind": "sample", "n": 1, "extent": [100, 100, 100]}));
    assert_eq!(status, 400);
    assert!(error_line(&v).contains("level-0 box"), "{v}");
    let (status, v) = s.post("/api/jobs", json!({"kind": "sample", "n": 0}));
    assert_eq!(status, 400, "{v}");
    let (status, v) = s.post("/api/jobs", json!({"kind": "launch_missiles"}));
    assert_eq!(status, 400, "{v}");
    let (status, v) = s.post("/api/jobs", json!({"kind": "keep", "shape": "variant_000"}));
    assert_eq!(status, 400, "{v}");
    assert!(error_line(&v).contains("already a variant of the run"));
    let (_, draft) = s.post("/api/drafts", json!({"source": "variant_000", "level": 1}));
    let voxels_before = draft["voxels"].as_u64().unwrap();
    for bad in [
        json!({"op": "delete", "box": {"min": [0, 0, 0], "max": [40, 3, 3]}}),
        json!({"op": "delete", "box": {"min": [0, 0, 0], "max": [0, 0, 0]}}),
        json!({"op": "paste", "to": [1, 1, 1]}),
        json!({"op": "move", "box": {"min": [0, 0, 0], "max": [31, 31, 31]}, "by": [20, 0, 0]}),
        json!({"op": "explode"}),
    ] {
        let (status, v) = s.post("/api/drafts/d1/edit", bad.clone());
        assert_eq!(status, 400, "{bad}: {v}");
        error_line(&v);
    }
    let (_, state) = s.get(state_path);
    assert_eq!(state["drafts"][0]["voxels"].as_u64(), Some(voxels_before), "refused edits changed the draft");
    assert_eq!(state["drafts"][0]["edits"], json!([]));
    assert_eq!(state["jobs"], json!([]), "a refused job was queued");
    // A delete mirrored across x: both sides in one step, one undo.
    let (status, v) = s.post("/api/drafts/d1/edit", json!({"op": "delete", "box": {"min": [0, 0, 0], "max": [9, 31, 31]}, "mirror": "x"}));
    assert_eq!(status, 200, "{v}");
    assert!(v["did"].as_str().unwrap().contains("mirror image across x"), "{v}");
    let v_mirrored = v["draft"]["voxels"].as_u64().unwrap();
    let (_, plain) = s.post("/api/drafts/d1/edit", json!({"op": "undo"}));
    assert_eq!(plain["draft"]["voxels"].as_u64(), Some(voxels_before), "one undo step undoes both sides");
    let (status, v) = s.post("/api/drafts/d1/edit", json!({"op": "delete", "box": {"min": [0, 0, 0], "max": [9, 31, 31]}, "mirror": "w"}));
    assert_eq!(status, 400, "an unknown mirror axis: {v}");
    let (_, one_side) = s.post("/api/drafts/d1/edit", json!({"op": "delete", "box": {"min": [0, 0, 0], "max": [9, 31, 31]}}));
    assert!(v_mirrored < one_side["draft"]["voxels"].as_u64().unwrap(), "the mirrored delete removed no more than one side: {one_side}");
    let (_, undone) = s.post("/api/drafts/d1/edit", json!({"op": "undo"}));
    assert_eq!(undone["draft"]["voxels"].as_u64(), Some(voxels_before));
    let (status, _) = s.get("/api/shapes/variant_000/levels/7/points");
    assert_eq!(status, 400);
    assert_eq!(s.request("DELETE", state_path, None, &[("X-Studio-Token", &s.token)]).0, 405);

    // 50 requests at once are all answered.
    let t = Instant::now();
    let answered: Vec<u16> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..50)
            .map(|i| {
                let s = &s;
                scope.spawn(move || {
                    let path = if i % 2 == 0 { "/api/state".to_string() } else { format!("/api/shapes/variant_00{}/levels/2/points", i % 2) };
                    s.request("GET", &path, None, &[("X-Studio-Token", &s.token)]).0
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert!(answered.iter().all(|&c| c == 200), "{answered:?}");
    eprintln!("50 concurrent requests answered in {:.2} s", t.elapsed().as_secs_f64());

    // Bounds: drafts and queued jobs past their number get 429 and one
    // line; finished jobs beyond those listed are forgotten.
    let mut made = Vec::new();
    let refused = loop {
        let (status, v) = s.post("/api/drafts", json!({"source": "variant_000", "level": 1}));
        if status != 200 {
            break (status, v);
        }
        made.push(v["id"].as_str().unwrap().to_string());
        assert!(made.len() <= 64, "drafts are not bounded");
    };
    assert_eq!(refused.0, 429, "{}", refused.1);
    assert!(error_line(&refused.1).contains("discard one first"), "{}", refused.1);
    for d in &made {
        assert_eq!(s.post(&format!("/api/drafts/{d}/discard"), json!({})).0, 200);
    }
    let mut asked = Vec::new();
    let refused = loop {
        let (status, v) = s.post("/api/jobs", json!({"kind": "sample", "n": 1, "seed": 1}));
        if status != 202 {
            break (status, v);
        }
        asked.push(v["id"].as_str().unwrap().to_string());
        assert!(asked.len() <= 100, "the queue is not bounded");
    };
    assert_eq!(refused.0, 429, "{}", refused.1);
    assert!(error_line(&refused.1).contains("jobs are waiting already"), "{}", refused.1);
    for j in &asked {
        s.post(&format!("/api/jobs/{j}/cancel"), json!({}));
    }
    for j in &asked {
        s.finish(j);
    }
    let (status, v) = s.post("/api/jobs", json!({"kind": "sample", "n": 1, "seed": 1}));
    assert_eq!(status, 202, "a queue that emptied takes jobs again: {v}");
    s.post(&format!("/api/jobs/{}/cancel", v["id"].as_str().unwrap()), json!({}));
    let listed = s.get(state_path).1["jobs"].as_array().unwrap().len();
    assert!(listed <= 33, "{listed} jobs listed: finished ones are not pruned");

    // A folder that is not a trained run: exit 2, one line, nothing written.
    let empty = tempfile::tempdir().unwrap();
    let o = shapeshifter(&["studio", empty.path().to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).lines().filter(|l| l.starts_with("error")).count() == 1 && stderr(&o).contains("no trained models here"), "{}", stderr(&o));
    assert_eq!(std::fs::read_dir(empty.path()).unwrap().count(), 0, "the studio wrote into a folder it refused");

    // The run folder is held: a run on it is refused while the studio serves.
    let o = shapeshifter(&["demo", "-o", s.run.to_str().unwrap(), "-n", "2"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("studio"), "the refusal names the holder: {}", stderr(&o));
}

#[test]
fn an_edit_regenerated_and_kept_is_a_variant_folder_that_differs_where_it_was_edited() {
    let s = Studio::start();
    let (status, draft) = s.post("/api/drafts", json!({"source": "variant_001", "level": 1}));
    assert_eq!(status, 200, "{draft}");
    // Delete the upper half of level 1 (32^3), undo, redo.
    let (status, v) = s.post("/api/drafts/d1/edit", json!({"op": "delete", "box": {"min": [0, 16, 0], "max": [31, 31, 31]}}));
    assert_eq!(status, 200, "{v}");
    let deleted = draft["voxels"].as_u64().unwrap() - v["draft"]["voxels"].as_u64().unwrap();
    assert!(deleted > 0);
    assert_eq!(s.post("/api/drafts/d1/edit", json!({"op": "undo"})).1["draft"]["voxels"], draft["voxels"]);
    assert_eq!(s.post("/api/drafts/d1/edit", json!({"op": "redo"})).1["draft"]["voxels"], v["draft"]["voxels"]);
    // Copy a box of the exemplar's level 1 and paste it beside: more voxels.
    let (status, c) = s.post("/api/drafts/d1/edit", json!({"op": "copy_exemplar", "box": {"min": [0, 0, 0], "max": [31, 6, 31]}}));
    assert_eq!(status, 200, "{c}");
    let (status, p) = s.post("/api/drafts/d1/edit", json!({"op": "paste", "to": [0, 0, 0]}));
    assert_eq!(status, 200, "{p}");
    assert!(p["did"].as_str().unwrap().contains("of the exemplar level 1"), "{p}");

    let (status, job) = s.post("/api/jobs", json!({"kind": "regenerate", "draft": "d1"}));
    assert_eq!(status, 202, "{job}");
    let job = s.finish(job["id"].as_str().unwrap());
    assert_eq!(job["state"], "done", "{job}");
    let shape = job["outputs"][0].as_str().unwrap().to_string();
    let made: Vec<u64> = job["levels"].as_array().unwrap().iter().map(|l| l["level"].as_u64().unwrap()).collect();
    assert_eq!(made, [2], "each level told as it was made: {job}");
    let (_, state) = s.get("/api/state");
    let new = state["shapes"].as_array().unwrap().iter().find(|v| v["id"] == shape.as_str()).unwrap().clone();
    assert_eq!(new["levels"], json!([1, 2]));
    assert!(new["verdict"]["by"].as_str().is_some(), "{new}");
    // Its points and preview are served.
    let (status, points) = s.request("GET", &format!("/api/shapes/{shape}/levels/2/points"), None, &[("X-Studio-Token", &s.token)]);
    assert_eq!(status, 200);
    assert_eq!(&points[..4], b"SSP1");
    let (status, png) = s.request("GET", &format!("/api/shapes/{shape}/preview.png"), None, &[("X-Studio-Token", &s.token)]);
    assert_eq!(status, 200);
    assert!(image::load_from_memory(&png).is_ok());

    // Keep: the next variant folder of the run, with its levels, previews,
    // mesh and record; in the USD asset and eval.json.
    let (status, job) = s.post("/api/jobs", json!({"kind": "keep", "shape": shape}));
    assert_eq!(status, 202, "{job}");
    // A person's job asked for after the keep runs before the run's
    // finishing work (mesh, USD, eval) that the keep queues.
    let (_, again) = s.post("/api/jobs", json!({"kind": "regenerate", "draft": "d1"}));
    let job = s.finish(job["id"].as_str().unwrap());
    assert_eq!(job["state"], "done", "{job}");
    // The folder is there at once; its mesh, the USD asset and the
    // evaluation follow in a finishing job.
    let folder = s.run.join("variants/variant_002");
    assert!(folder.join("level_2.vdb").is_file() && folder.join("studio.json").is_file());
    let (_, state) = s.get("/api/state");
    let finishing = state["jobs"].as_array().unwrap().iter().find(|j| j["kind"] == "finish").expect("a finishing job").clone();
    let finishing = s.finish(finishing["id"].as_str().unwrap());
    assert_eq!(finishing["state"], "done", "{finishing}");
    let again = s.finish(again["id"].as_str().unwrap());
    assert!(again["started"].as_u64() < finishing["started"].as_u64(), "the regeneration waited for the finishing work: {again} {finishing}");
    for f in ["level_1.vdb", "level_2.vdb", "level_2.points.vdb", "level_2.png", "mesh.ply", "studio.json", "stage_sample.json"] {
        assert!(folder.join(f).is_file(), "{} lacks {f}", folder.display());
    }
    assert!(!s.run.join("variants/.variant_002.partial").exists());
    let usd = std::fs::read_to_string(s.run.join("variants.usda")).unwrap();
    assert!(usd.contains("variant_002"), "the USD asset does not name the kept variant");
    let eval: Value = serde_json::from_slice(&std::fs::read(s.run.join("eval.json")).unwrap()).unwrap();
    assert!(eval["variants"].as_array().unwrap().iter().any(|v| v["name"] == "variant_002"));
    let record: Value = serde_json::from_slice(&std::fs::read(folder.join("studio.json")).unwrap()).unwrap();
    assert!(record["made_by"].as_str().unwrap().contains("edit of variant_001 at level 1"), "{record}");
    let (_, state) = s.get("/api/state");
    assert_eq!(record["compute"], state["compute"], "the record says how the products were made");
    assert!(["f32", "bf16"].contains(&record["compute"].as_str().unwrap()));
    // It reads back and differs from its source where it was edited: no
    // voxel of its level 1 is in the deleted upper half but the pasted
    // exemplar's (which lie in y < 7).
    let (kept1, _) = shapeshifter::io::vdb::read_level(&folder.join("level_1.vdb")).unwrap();
    let (source1, _) = shapeshifter::io::vdb::read_level(&s.run.join("variants/variant_001/level_1.vdb")).unwrap();
    assert!(kept1.coords.iter().all(|c| c.y < 16), "voxels left in the deleted box");
    assert!(source1.coords.iter().any(|c| c.y >= 16), "the source had voxels there");
    assert_ne!(voxels(&folder.join("level_2.vdb")), 0);
    // The gallery lists it as a run variant now; keeping it again is refused.
    let (_, state) = s.get("/api/state");
    assert!(state["shapes"].as_array().unwrap().iter().any(|v| v["id"] == "variant_002" && v["verdict"]["by"] == "eval.json"));
    let (status, v) = s.post("/api/jobs", json!({"kind": "keep", "shape": shape}));
    assert_eq!(status, 400);
    assert!(error_line(&v).contains("already kept as variant_002"));

    // A variant sampled in a longer box keeps its extent when kept: eval
    // judges it against the exemplar at that extent, as sampling did.
    let (status, job) = s.post("/api/jobs", json!({"kind": "sample", "n": 1, "extent": [1.25, 1, 1]}));
    assert_eq!(status, 202, "{job}");
    let job = s.finish(job["id"].as_str().unwrap());
    assert_eq!(job["state"], "done", "{job}");
    let longer = job["outputs"][0].as_str().expect("the sampled shape").to_string();
    let (status, job) = s.post("/api/jobs", json!({"kind": "keep", "shape": longer}));
    assert_eq!(status, 202, "{job}");
    assert_eq!(s.finish(job["id"].as_str().unwrap())["state"], "done");
    let extent: Value = serde_json::from_slice(&std::fs::read(s.run.join("variants/variant_003/extent.json")).expect("extent.json kept")).unwrap();
    assert_eq!(extent["extent"], json!([1.25, 1.0, 1.0]), "{extent}");
    let (_, state) = s.get("/api/state");
    if let Some(f) = state["jobs"].as_array().unwrap().iter().find(|j| j["kind"] == "finish" && j["state"] != "done") {
        assert_eq!(s.finish(f["id"].as_str().unwrap())["state"], "done");
    }

    // A later `run` with more variants leaves the kept folder as it is.
    let (code, _, run, _dir) = s.signal(libc::SIGINT, Duration::from_secs(10));
    assert_eq!(code, Some(130));
    let before = std::fs::read(run.join("variants/variant_002/level_2.vdb")).unwrap();
    let o = shapeshifter(&["sample", run.join("exemplar").to_str().unwrap(), "--models", run.join("models").to_str().unwrap(), "-o", run.join("variants").to_str().unwrap(), "-n", "3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("kept from the studio: left as it is"), "{}", stderr(&o));
    assert_eq!(std::fs::read(run.join("variants/variant_002/level_2.vdb")).unwrap(), before);
}

#[test]
fn a_cancelled_job_leaves_nothing_and_sigterm_ends_the_studio_within_seconds() {
    let s = Studio::start();
    let (_, a) = s.post("/api/jobs", json!({"kind": "sample", "n": 16, "seed": 5}));
    let (_, b) = s.post("/api/jobs", json!({"kind": "sample", "n": 1, "seed": 6}));
    let (a, b) = (a["id"].as_str().unwrap().to_string(), b["id"].as_str().unwrap().to_string());
    // The second queues behind the first; cancelling the queued one
    // cancels it at once, the running one between steps.
    assert_eq!(s.get(&format!("/api/jobs/{b}")).1["state"], "queued");
    assert_eq!(s.post(&format!("/api/jobs/{b}/cancel"), json!({})).1["state"], "cancelled");
    let t = Instant::now();
    while s.get(&format!("/api/jobs/{a}")).1["state"] == "queued" {
        assert!(t.elapsed() < Duration::from_secs(30));
        std::thread::sleep(Duration::from_millis(20));
    }
    s.post(&format!("/api/jobs/{a}/cancel"), json!({}));
    let ja = s.finish(&a);
    assert_eq!(ja["state"], "cancelled", "{ja}");
    // Only whole variants stay in the gallery (none or those finished
    // before the cancel), each with its verdict.
    let (_, state) = s.get("/api/state");
    for v in state["shapes"].as_array().unwrap().iter().filter(|v| v["origin"]["kind"] == "session") {
        assert!(!v["verdict"].is_null(), "an unfinished variant stayed: {v}");
    }
    // A job running when SIGTERM comes: the studio ends within seconds,
    // 143, nothing half-written in the run.
    let (_, j) = s.post("/api/jobs", json!({"kind": "sample", "n": 16}));
    let id = j["id"].as_str().unwrap().to_string();
    while s.get(&format!("/api/jobs/{id}")).1["state"] == "queued" {
        std::thread::sleep(Duration::from_millis(20));
    }
    let (code, took, run, _dir) = s.signal(libc::SIGTERM, Duration::from_secs(10));
    assert_eq!(code, Some(143));
    assert!(took < Duration::from_secs(5), "took {took:?}");
    let names: Vec<String> = std::fs::read_dir(run.join("variants")).unwrap().flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect();
    let mut names = names;
    names.sort();
    assert_eq!(names, ["variant_000", "variant_001"], "the studio wrote into the run");
}

/// The status of the answer on `c`, if one arrives before the connection ends.
fn read_status(c: &mut std::net::TcpStream) -> Option<u16> {
    c.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let mut line = String::new();
    BufReader::new(c).read_line(&mut line).ok()?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// The studio's resident memory, KiB.
fn rss_kib(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    status.lines().find_map(|l| l.strip_prefix("VmRSS:")).and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok()).unwrap()
}

/// What anyone on the machine can send, without the token, crashes,
/// freezes or slows nothing: a false huge Content-Length (tiny_http
/// allocated it and aborted), 300 idle connections and 8 that send a head
/// and no body (8 handler threads froze), a 1 MB header line (memory grew
/// by its size). After each, the state answers within a second.
#[test]
fn the_studio_survives_what_anyone_on_the_machine_can_send() {
    use std::io::Write;
    use std::net::TcpStream;
    let s = Studio::start();
    let authority = s.base.strip_prefix("http://").unwrap().to_string();
    let answers_fast = |after: &str| {
        let t = Instant::now();
        let (status, _) = s.get("/api/state");
        assert_eq!(status, 200, "after {after}");
        assert!(t.elapsed() < Duration::from_secs(1), "after {after}: {:.2} s", t.elapsed().as_secs_f64());
    };
    for token in ["", s.token.as_str()] {
        let mut c = TcpStream::connect(&authority).unwrap();
        let t = if token.is_empty() { String::new() } else { format!("X-Studio-Token: {token}\r\n") };
        write!(c, "POST /api/drafts HTTP/1.1\r\nHost: {authority}\r\n{t}Content-Type: application/json\r\nContent-Length: 999999999999999\r\n\r\n").unwrap();
        assert_eq!(read_status(&mut c), Some(if token.is_empty() { 403 } else { 413 }));
    }
    assert!(s.child_alive(), "a false Content-Length ended the studio");
    answers_fast("a false huge Content-Length");

    let idle: Vec<TcpStream> = (0..300).map(|_| TcpStream::connect(&authority).unwrap()).collect();
    let stalled: Vec<TcpStream> = (0..8)
        .map(|_| {
            let mut c = TcpStream::connect(&authority).unwrap();
            write!(c, "POST /api/drafts HTTP/1.1\r\nHost: {authority}\r\nX-Studio-Token: {}\r\nContent-Type: application/json\r\nContent-Length: 100\r\n\r\n", s.token).unwrap();
            c
        })
        .collect();
    std::thread::sleep(Duration::from_millis(300));
    answers_fast("300 idle connections and 8 bodies that never come");
    drop((idle, stalled));

    let before = rss_kib(s.child.id());
    let mut c = TcpStream::connect(&authority).unwrap();
    c.set_write_timeout(Some(Duration::from_secs(10))).unwrap();
    let line = format!("GET /api/state HTTP/1.1\r\nHost: {authority}\r\nX-Big: {}\r\n\r\n", "a".repeat(1 << 20));
    // The studio answers before the line ends and closes: the rest of the
    // write may be refused.
    let _ = c.write_all(line.as_bytes());
    let status = read_status(&mut c);
    assert!(matches!(status, Some(431) | Some(400) | None), "a 1 MB header line: {status:?}");
    let grown = rss_kib(s.child.id()).saturating_sub(before);
    assert!(grown < 8 * 1024, "a 1 MB header line grew the studio by {grown} KiB");
    answers_fast("a 1 MB header line");
}

/// Out of file descriptors, the studio stops taking connections for a
/// while, and takes them again when some close (tiny_http's accept thread
/// ended for good, and the studio refused every connection until killed).
#[test]
fn the_studio_takes_connections_again_after_running_out_of_files() {
    use std::net::TcpStream;
    let s = Studio::start_with_files(Some(256));
    let authority = s.base.strip_prefix("http://").unwrap().to_string();
    // More connections than the studio may hold files: the last ones wait
    // in the listen queue or are refused.
    let flood: Vec<TcpStream> = (0..320).filter_map(|_| TcpStream::connect_timeout(&authority.parse().unwrap(), Duration::from_secs(1)).ok()).collect();
    std::thread::sleep(Duration::from_millis(500));
    drop(flood);
    let t = Instant::now();
    loop {
        let answered = std::panic::catch_unwind(|| s.get("/api/state").0).ok();
        if answered == Some(200) {
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(15), "the studio never took connections again ({answered:?})");
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(s.child_alive());
    eprintln!("answering again {:.2} s after the flood closed", t.elapsed().as_secs_f64());
}

/// Keeping is finished by a job (mesh, USD asset, eval.json), and a kept
/// variant is marked finished last (`stage_kept.json`): a studio stopped
/// while finishing ends within 2 s, and the next studio on the run finishes
/// what was missing.
#[test]
fn a_stop_while_finishing_a_keep_is_finished_when_the_run_reopens() {
    let s = Studio::start();
    let (status, job) = s.post("/api/jobs", json!({"kind": "sample", "n": 1, "seed": 3}));
    assert_eq!(status, 202, "{job}");
    let job = s.finish(job["id"].as_str().unwrap());
    assert_eq!(job["state"], "done", "{job}");
    let shape = job["outputs"][0].as_str().unwrap().to_string();
    // A draft left open, with an edit: the next studio on the run reopens it.
    let (_, draft) = s.post("/api/drafts", json!({"source": "variant_001", "level": 1}));
    let (status, edited) = s.post(&format!("/api/drafts/{}/edit", draft["id"].as_str().unwrap()), json!({"op": "delete", "box": {"min": [0, 0, 0], "max": [12, 31, 31]}}));
    assert_eq!(status, 200, "{edited}");
    let (status, job) = s.post("/api/jobs", json!({"kind": "keep", "shape": shape}));
    assert_eq!(status, 202, "{job}");
    s.finish(job["id"].as_str().unwrap());
    // Stopped once finishing has begun (past its meshing, where there is
    // time to: the USD asset and the evaluation).
    let t = Instant::now();
    loop {
        let (_, state) = s.get("/api/state");
        let finishing = state["jobs"].as_array().unwrap().iter().find(|j| j["kind"] == "finish").cloned();
        let message = finishing.as_ref().and_then(|j| j["message"].as_str()).unwrap_or("").to_string();
        if message.contains("USD") || message.contains("evaluating") {
            break;
        }
        assert!(finishing.is_none_or(|j| j["state"] != "done"), "finishing ended before it could be stopped");
        assert!(t.elapsed() < Duration::from_secs(120), "finishing never began: {state}");
        std::thread::sleep(Duration::from_millis(10));
    }
    let (code, took, run, dir) = s.signal(libc::SIGTERM, Duration::from_secs(10));
    assert_eq!(code, Some(143));
    assert!(took < Duration::from_secs(2), "SIGTERM while finishing took {took:?}");
    let kept = run.join("variants/variant_002");
    assert!(kept.join("studio.json").is_file() && !kept.join("stage_kept.json").exists(), "the stop came after finishing");
    // The next studio on the run finishes it.
    let s = Studio::launch(run.clone(), dir, None);
    let t = Instant::now();
    while !kept.join("stage_kept.json").is_file() {
        assert!(t.elapsed() < Duration::from_secs(120), "the reopened studio did not finish the kept variant: {}", s.get("/api/state").1["jobs"]);
        std::thread::sleep(Duration::from_millis(100));
    }
    let usd = std::fs::read_to_string(run.join("variants.usda")).unwrap();
    assert!(usd.contains("variant_002"), "the kept variant is not in the USD asset");
    let eval: Value = serde_json::from_slice(&std::fs::read(run.join("eval.json")).unwrap()).unwrap();
    assert_eq!(eval["variants"].as_array().unwrap().len(), 3, "the kept variant is not in eval.json");
    assert!(kept.join("mesh.ply").is_file());
    let (_, state) = s.get("/api/state");
    let reopened = &state["drafts"][0];
    assert_eq!((&reopened["id"], &reopened["source"], &reopened["voxels"]), (&edited["draft"]["id"], &json!("variant_001"), &edited["draft"]["voxels"]), "{state}");
    let (_, another) = s.post("/api/drafts", json!({"source": "variant_000", "level": 1}));
    assert_ne!(another["id"], reopened["id"], "a new draft took a reopened draft's id");
    let (status, job) = s.post("/api/jobs", json!({"kind": "regenerate", "draft": reopened["id"]}));
    assert_eq!(status, 202, "a reopened draft regenerates: {job}");
    assert_eq!(s.finish(job["id"].as_str().unwrap())["state"], "done");
    s.post(&format!("/api/drafts/{}/discard", reopened["id"].as_str().unwrap()), json!({}));
    assert!(!run.join(format!("studio_drafts/{}.json", reopened["id"].as_str().unwrap())).exists(), "a discarded draft stays saved");
}
