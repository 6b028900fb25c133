#!/usr/bin/env python3
"""A studio session driven through its HTTP API, as a script would drive it: the
session of docs/studio.md ("Sessions"), repeatable. It opens a copy of RUN (kept
variants are written into the run folder, so the original stays as it is), then:

  1. deletes the top of a variant's 32^3 level (level 1) and regenerates it;
  2. replaces the top of another variant's level 1 by the exemplar's (copy from the
     exemplar, delete, paste) and regenerates it, then keeps the result;
  3. asks for two more variants like a third one, its levels to 32^3 kept;
  4. asks for two new variants (seed 21).

For each step it prints a row: the seconds from the request to each level ready (the
job's own clock), the judge's verdict, and the PNG it saved for the eye; and the keep's
time and the run's finishing work (mesh, USD, eval), waited for before the next step.

    scripts/studio-session.py RUN OUT [--bin target/release/shapeshifter]
        [--delete V] [--paste V] [--like V]     (variant numbers; default 7, 2, 4)
        [--minutes M]

With --minutes M, the session goes on for M minutes more in rounds (a delete at
level 1 regenerated, one more like a variant, one new variant, the draft discarded,
the shapes left in the gallery as a person leaves them) and prints the studio's
resident memory after each round (memory.csv in OUT): what a long session costs.

Standard library only (urllib), so any Python 3 runs it.
"""
import argparse
import json
import shutil
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path


class Studio:
    def __init__(self, binary, run):
        self.proc = subprocess.Popen([binary, "studio", str(run), "--port", "0"], stdout=subprocess.PIPE,
                                     stderr=subprocess.DEVNULL, text=True)
        line = self.proc.stdout.readline().strip()
        if not line.startswith("studio: "):
            sys.exit(f"studio-session: the studio printed no address: {line!r}")
        self.base, self.token = line[len("studio: "):].split("/?token=")
        t = time.time()
        while not self.get("/api/state").get("ready"):
            if time.time() - t > 120:
                sys.exit("studio-session: the networks never loaded")
            time.sleep(0.05)

    def call(self, method, path, body=None, raw=False):
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.base + path, data=data, method=method,
                                     headers={"X-Studio-Token": self.token, "Content-Type": "application/json"})
        try:
            with urllib.request.urlopen(req, timeout=600) as r:
                payload = r.read()
        except urllib.error.HTTPError as e:
            sys.exit(f"studio-session: {method} {path}: {e.code} {e.read().decode(errors='replace')}")
        return payload if raw else json.loads(payload)

    def get(self, path):
        return self.call("GET", path)

    def post(self, path, body):
        return self.call("POST", path, body)

    def finish(self, job):
        while True:
            j = self.get(f"/api/jobs/{job['id']}")
            if j["state"] in ("done", "failed", "cancelled"):
                if j["state"] != "done":
                    sys.exit(f"studio-session: job {j['id']} {j['state']}: {j.get('message')}")
                return j
            time.sleep(0.05)

    def shape(self, shape_id):
        return next(s for s in self.get("/api/state")["shapes"] if s["id"] == shape_id)

    def rss_mib(self):
        """The studio's resident memory, MiB (Linux)."""
        for line in Path(f"/proc/{self.proc.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
        return float("nan")

    def close(self):
        self.proc.terminate()
        self.proc.wait(timeout=60)


def verdict(v):
    if not v:
        return "not judged"
    flags = [f for f in v["flags"] if f != "near_copy"]
    words = ", ".join(flags) if flags else "whole"
    return words + (" (near copy)" if v["near_copy"] else "")


def ready(job):
    """Seconds from the request to each level ready, per output shape."""
    per = {}
    for lv in job["levels"]:
        per.setdefault(lv["shape"], []).append(f"{lv['resolution']}^3 {lv['since_asked']:.2f}")
    return per


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run")
    ap.add_argument("out")
    ap.add_argument("--bin", default=str(Path(__file__).resolve().parent.parent / "target/release/shapeshifter"))
    ap.add_argument("--delete", type=int, default=7)
    ap.add_argument("--paste", type=int, default=2)
    ap.add_argument("--like", type=int, default=4)
    ap.add_argument("--minutes", type=float, default=0.0)
    a = ap.parse_args()
    out = Path(a.out)
    if out.exists():
        sys.exit(f"studio-session: {out} exists: name a new folder")
    out.mkdir(parents=True)
    run = out / "run"
    shutil.copytree(a.run, run, ignore=shutil.ignore_patterns("*.lock"))
    s = Studio(a.bin, run)
    rows = []
    try:
        res = s.get("/api/state")["resolutions"]
        top = res[1] - 1  # the last voxel of level 1 (32^3: 31)

        def record(new, what, levels):
            """One table row for a made shape, its preview saved beside."""
            png = out / f"{new}.png"
            png.write_bytes(s.call("GET", f"/api/shapes/{new}/preview.png", raw=True))
            rows.append((what, " / ".join(levels), verdict(s.shape(new)["verdict"]), png.name))

        def regenerate(draft, what):
            job = s.finish(s.post("/api/jobs", {"kind": "regenerate", "draft": draft}))
            new = job["outputs"][0]
            record(new, what, ready(job)[new])
            return new

        # 1. The top of a variant deleted at level 1.
        src = f"variant_{a.delete:03d}"
        draft = s.post("/api/drafts", {"source": src, "level": 1})
        d = draft["id"]
        lo = int(top * 0.65)
        e = s.post(f"/api/drafts/{d}/edit", {"op": "delete", "box": {"min": [0, lo, 0], "max": [top, top, top]}})
        gone = draft["voxels"] - e["draft"]["voxels"]
        regenerate(d, f"`{src}`, level 1: deleted the top (y {lo}-{top}, {gone} voxels), regenerated")

        # 2. Another variant's top replaced by the exemplar's, regenerated, kept.
        src = f"variant_{a.paste:03d}"
        d = s.post("/api/drafts", {"source": src, "level": 1})["id"]
        lo = int(top * 0.6)
        box = {"min": [0, lo, 0], "max": [top, top, top]}
        s.post(f"/api/drafts/{d}/edit", {"op": "copy_exemplar", "box": box})
        s.post(f"/api/drafts/{d}/edit", {"op": "delete", "box": box})
        s.post(f"/api/drafts/{d}/edit", {"op": "paste", "to": [0, lo, 0]})
        pasted = regenerate(d, f"`{src}`, level 1: its top (y {lo}-{top}) replaced by the exemplar's, regenerated")
        t = time.time()
        keep = s.finish(s.post("/api/jobs", {"kind": "keep", "shape": pasted}))
        kept_in = time.time() - t
        kept = Path(keep["message"].split("kept as ", 1)[-1].split(";")[0]).name
        # The keep queues the run's finishing work (its mesh, the USD asset,
        # eval.json over every variant); waited for here, so that the next
        # steps' times are their own.
        finishing = [j for j in s.get("/api/state")["jobs"] if j["kind"] == "finish"]
        fin = s.finish(finishing[-1]) if finishing else None

        # 3. More like a third variant, its levels to 32^3 kept.
        src = f"variant_{a.like:03d}"
        job = s.finish(s.post("/api/jobs", {"kind": "more_like", "source": src, "keep_level": 1, "n": 2}))
        for new, levels in ready(job).items():
            record(new, f"more like `{src}` (levels to 32^3 kept)", levels)

        # 4. Two new variants.
        job = s.finish(s.post("/api/jobs", {"kind": "sample", "n": 2, "seed": 21}))
        for new, levels in ready(job).items():
            record(new, "a new variant (seed 21)", levels)

        # 5. The long session: rounds until --minutes pass, memory after each.
        if a.minutes > 0:
            memory = [("minutes", "round", "shapes", "rss_mib")]
            t0, k = time.time(), 0
            while time.time() - t0 < a.minutes * 60:
                k += 1
                src = f"variant_{(a.delete + k) % 10:03d}"
                d = s.post("/api/drafts", {"source": src, "level": 1})["id"]
                lo = int(top * (0.4 + 0.05 * (k % 6)))
                s.post(f"/api/drafts/{d}/edit", {"op": "delete", "box": {"min": [0, lo, 0], "max": [top, top, top]}})
                s.finish(s.post("/api/jobs", {"kind": "regenerate", "draft": d}))
                s.post(f"/api/drafts/{d}/discard", {})
                s.finish(s.post("/api/jobs", {"kind": "more_like", "source": src, "keep_level": 1, "n": 1}))
                s.finish(s.post("/api/jobs", {"kind": "sample", "n": 1, "seed": 100 + k}))
                shapes = len(s.get("/api/state")["shapes"])
                memory.append((f"{(time.time() - t0) / 60:.1f}", k, shapes, f"{s.rss_mib():.0f}"))
                print("studio-session: " + ", ".join(f"{h} {v}" for h, v in zip(memory[0], memory[-1])), file=sys.stderr)
            (out / "memory.csv").write_text("\n".join(",".join(map(str, r)) for r in memory) + "\n")

    finally:
        s.close()
    print("| what | seconds from the request to each level ready | judge | picture |")
    print("|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(r) + " |")
    print(f"\nkept as {kept}: the folder in {kept_in:.1f} s; the finishing work "
          + (f"{fin['seconds']:.0f} s" if fin else "not queued"))
    (out / "session.json").write_text(json.dumps({"rows": rows, "kept": kept, "keep_s": kept_in,
                                                  "finish_s": fin["seconds"] if fin else None}, indent=1))


if __name__ == "__main__":
    main()
