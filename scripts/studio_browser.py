"""Drives the studio page in a real headless Chromium through WebDriver
(Debian's chromium-driver, the selenium client): load, pick a variant, select
a box at level 1 with the mouse, delete it, undo and redo with the keys,
regenerate the finer levels, keep the result. Checks what the page shows and
what the run folder holds after, saves a screenshot of the page, and prints
the page's own timings (edit -> each level on screen).

usage: STUDIO_URL=URL studio_browser.py RUN_DIR SCREENSHOT.png
(the address holds the session's token: it is not put on a command line,
where any user of the machine could read it)
"""
import json
import os
import subprocess
import sys
import time

from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys

URL = os.environ["STUDIO_URL"]
RUN, SHOT = sys.argv[1], sys.argv[2]
BIN = os.environ.get("SHAPESHIFTER", "target/release/shapeshifter")


def fail(msg):
    print(f"studio-test: FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


def wait(what, cond, timeout=120.0):
    end = time.time() + timeout
    while time.time() < end:
        try:
            v = cond()
            if v:
                return v
        except Exception:  # the page may be between states
            pass
        time.sleep(0.1)
    fail(f"timed out waiting for {what}")


opts = webdriver.ChromeOptions()
opts.binary_location = "/usr/bin/chromium"
for a in ["--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--no-first-run",
          "--disable-background-networking", "--disable-component-update", "--disable-sync",
          "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist",
          "--window-size=1500,900"]:
    opts.add_argument(a)
driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=opts)
try:
    js = driver.execute_script
    state = lambda: js("return window.studio && window.studio.state")

    # Load: the page, the networks, the gallery.
    driver.get(URL)
    wait("the page to load", lambda: js("return document.body.dataset.loaded") == "1", 60)
    # The token leaves the address bar once the page has its cookie.
    if "token=" in driver.current_url:
        fail(f"the token stays in the address bar: {driver.current_url}")
    # The Content-Security-Policy: the page itself breaks none of it (its
    # import map and scripts load), and a script put into the page as markup
    # does not run.
    js("window.__violations = []; document.addEventListener('securitypolicyviolation', (e) => window.__violations.push(e.violatedDirective + ' ' + e.blockedURI));")
    js("const s = document.createElement('script'); s.textContent = 'window.__inline = 1'; document.body.appendChild(s);")
    time.sleep(0.3)
    if js("return window.__inline === 1"):
        fail("an inline script ran: the page has no Content-Security-Policy")
    print("studio-test: the token left the address bar; an inline script put into the page was blocked by its policy")
    wait("the networks", lambda: state()["ready"], 120)
    if state().get("load_error"):
        fail(f"networks: {state()['load_error']}")
    cards = driver.find_elements(By.CSS_SELECTOR, "#gallery .card")
    print(f"studio-test: page loaded, {len(cards)} shapes in the gallery")
    if len(cards) < 2:
        fail("the gallery shows no variant")
    hostile = os.environ.get("STUDIO_HOSTILE_FLAG")
    if hostile:
        # A flag of eval.json that is markup: shown as text, and no script ran.
        wait("the markup flag shown as text", lambda: any(hostile in c.text for c in driver.find_elements(By.CSS_SELECTOR, "#gallery .card")), 30)
        time.sleep(1.0)  # an injected image's onerror would have fired by now
        if js("return window.__xss === 1"):
            fail("a flag from eval.json ran as script in the page")
        if driver.find_elements(By.CSS_SELECTOR, '#gallery img[src="x"]'):
            fail("a flag from eval.json became an element of the page")
        print("studio-test: a flag holding markup in eval.json is shown as text; no script ran")
    webgl = js("const c = document.createElement('canvas'); return !!(c.getContext('webgl2') || c.getContext('webgl'))")
    if not webgl:
        fail("this Chromium gives the page no WebGL")

    # Pick the first run variant.
    source = next(c.get_attribute("data-id") for c in cards if c.get_attribute("data-id").startswith("variant_"))
    driver.find_element(By.CSS_SELECTOR, f'#gallery .card[data-id="{source}"]').click()
    wait(f"{source} in the view", lambda: driver.find_element(By.ID, "left-label").text.startswith(source))

    # Edit level 1: a box selected with the mouse (shift+drag over the
    # middle of the left view), then deleted.
    driver.find_element(By.CSS_SELECTOR, '#edit-level option[value="1"]').click()
    driver.find_element(By.ID, "start-edit").click()
    wait("the editor", lambda: driver.find_element(By.ID, "editor").is_displayed())
    wait("the draft in the view", lambda: "level 1" in driver.find_element(By.ID, "left-label").text)
    canvas = driver.find_element(By.ID, "canvas")
    w, h = canvas.size["width"], canvas.size["height"]
    # Offsets are from the canvas centre: the left view's middle is at -w/4.
    # The rectangle covers the top of the shape across its width.
    (ActionChains(driver).move_to_element_with_offset(canvas, int(-w / 4 - w * 0.2), int(-h * 0.4))
        .key_down(Keys.SHIFT).click_and_hold().move_by_offset(int(w * 0.4), int(h * 0.22)).release().key_up(Keys.SHIFT).perform())
    box = wait("a box from the mouse", lambda: js("return window.studio.box"), 10)
    print(f"studio-test: box selected with the mouse: {box['min']}..{box['max']}")
    driver.find_element(By.ID, "op-delete").click()
    wait("the delete", lambda: "1 edit(s)" in driver.find_element(By.ID, "draft-info").text)
    deleted = int(driver.find_element(By.ID, "draft-info").text.split("deleted ")[1].split(" ")[0])
    print(f"studio-test: deleted {deleted} voxels at level 1")
    body = driver.find_element(By.TAG_NAME, "body")
    body.send_keys(Keys.CONTROL, "z")
    wait("undo by the keys", lambda: "0 edit(s)" in driver.find_element(By.ID, "draft-info").text, 10)
    body.send_keys(Keys.CONTROL, "y")
    wait("redo by the keys", lambda: "1 edit(s)" in driver.find_element(By.ID, "draft-info").text, 10)
    print("studio-test: undo (Ctrl+Z) and redo (Ctrl+Y) by the keys")

    # Regenerate: the new variant's levels appear one by one; wait for the verdict.
    before = {s["id"] for s in state()["shapes"]}
    driver.find_element(By.ID, "regenerate").click()
    new = wait("a new variant", lambda: [s for s in state()["shapes"] if s["id"] not in before], 60)[0]["id"]
    finest = len(state()["resolutions"]) - 1
    wait(f"{new} judged", lambda: next(s for s in state()["shapes"] if s["id"] == new)["verdict"], 180)
    wait(f"{new} level {finest} on screen", lambda: any(t["shape"] == new and t["level"] == finest for t in js("return window.studio.timings")), 30)
    timings = [t for t in js("return window.studio.timings") if t["shape"] == new]
    for t in timings:
        print(f"studio-test: edit -> level {t['level']} ({t['resolution']}^3) on screen in {t['ms'] / 1000:.2f} s")
    shape = next(s for s in state()["shapes"] if s["id"] == new)
    print(f"studio-test: {new} made, levels {shape['levels']}, verdict {shape['verdict']}")

    # The 3D view is not blank: pixels other than the background colour in
    # both halves (the variant and the exemplar).
    counts = js("""
        const c = document.getElementById('canvas');
        const t = document.createElement('canvas'); t.width = c.width; t.height = c.height;
        const g = t.getContext('2d'); g.drawImage(c, 0, 0);
        const d = g.getImageData(0, 0, t.width, t.height).data;
        let left = 0, right = 0;
        for (let y = 0; y < t.height; y += 2) for (let x = 0; x < t.width; x += 2) {
          const i = 4 * (y * t.width + x);
          const bg = Math.abs(d[i] - 0x2a) + Math.abs(d[i + 1] - 0x2c) + Math.abs(d[i + 2] - 0x32) < 12;
          if (!bg) { if (x < t.width / 2) left++; else right++; }
        }
        return [left, right];""")
    print(f"studio-test: 3D view: {counts[0]} drawn pixels left (variant), {counts[1]} right (exemplar), sampled every 2nd")
    if counts[0] < 200 or counts[1] < 200:
        fail(f"the 3D view is blank: {counts}")
    driver.save_screenshot(SHOT)
    # Only the probe above was blocked: the page's own work broke no rule.
    violations = [v for v in js("return window.__violations") if not v.startswith("script-src-elem inline")]
    if violations:
        fail(f"the page broke its own Content-Security-Policy: {violations}")
    print(f"studio-test: screenshot {SHOT}")

    # Keep: a variant folder in the run, meshed, in the USD asset and eval.json.
    driver.find_element(By.ID, "keep").click()
    kept = wait("the keep", lambda: next(s for s in state()["shapes"] if s["id"] == new)["kept_as"], 300)
    job = [j for j in state()["jobs"] if j["kind"] == "keep"][-1]
    wait("the keep job", lambda: [j for j in state()["jobs"] if j["id"] == job["id"]][0]["state"] == "done", 300)
    # Its mesh, the USD asset and the evaluation follow in a finishing job.
    wait("the finishing job", lambda: [j for j in state()["jobs"] if j["kind"] == "finish"] and
         all(j["state"] == "done" for j in state()["jobs"] if j["kind"] == "finish"), 300)
    folder = os.path.join(RUN, "variants", kept)
    files = sorted(os.listdir(folder))
    print(f"studio-test: kept as {kept}: {' '.join(files)}")
    for f in ["level_1.vdb", f"level_{finest}.vdb", "mesh.ply", "studio.json", f"level_{finest}.png"]:
        if f not in files:
            fail(f"{folder} has no {f}")
    usd = open(os.path.join(RUN, "variants.usda")).read()
    if kept not in usd:
        fail(f"variants.usda does not name {kept}")
    ev = json.load(open(os.path.join(RUN, "eval.json")))
    if kept not in [v["name"] for v in ev["variants"]]:
        fail(f"eval.json does not score {kept}")

    # It reads back, and differs from its source where it was edited: level 1
    # holds the source's voxels less the deleted ones.
    def voxels(path):
        out = subprocess.run([BIN, "info", "--json", path], capture_output=True, text=True, check=True).stdout
        return json.loads(out)["outcomes"][0]["result"]
    a = voxels(os.path.join(RUN, "variants", source, "level_1.vdb"))
    b = voxels(os.path.join(folder, "level_1.vdb"))
    count = lambda rec: max(g.get("active_voxels", 0) for g in rec.get("grids", [{}]))
    print(f"studio-test: level 1 of {source}: {count(a)} voxels; of {kept}: {count(b)} ({deleted} deleted in the page)")
    if count(a) - count(b) != deleted:
        fail(f"{kept}'s level 1 is not {source}'s less the {deleted} deleted voxels")
    print("studio-test: PASS")
finally:
    driver.quit()
