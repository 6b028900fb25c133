"""Binary layers hold the text layers' scene (`make interop`).

usage: usd_binary_check.py TEXT_RUN BINARY_RUN

For the asset (variants.usda / variants.usdc) and every variant layer
(variants/*/variant.usda / .usdc): usd-core opens both, and each layer's
scene description, printed by usd-core as text, is the same (the binary
asset's references name .usdc layers where the text's name .usda). Prints
the files' sizes and usd-core's median time to open each layer and read its
mesh points (5 opens), and exits 1 on the first difference.
"""
import glob
import os
import statistics
import sys
import time

from pxr import Sdf, Usd


def fail(msg):
    print(f"interop: binary USD check failed: {msg}", file=sys.stderr)
    sys.exit(1)


def open_time(path):
    """Median seconds to open a layer's stage and read every mesh's points."""
    times = []
    for _ in range(5):
        if Sdf.Layer.Find(path):
            fail(f"{path} still open: the time would not include reading it")
        t = time.perf_counter()
        stage = Usd.Stage.Open(path, Usd.Stage.LoadAll)
        for prim in stage.Traverse():
            if prim.GetTypeName() in ("Mesh", "Points"):
                prim.GetAttribute("points").Get()
        times.append(time.perf_counter() - t)
        del stage
    return statistics.median(times)


def main():
    text_run, binary_run = sys.argv[1], sys.argv[2]
    pairs = [(os.path.join(text_run, "variants.usda"), os.path.join(binary_run, "variants.usdc"))]
    for t in sorted(glob.glob(os.path.join(text_run, "variants", "*", "variant.usda"))):
        rel = os.path.relpath(t, text_run)
        pairs.append((t, os.path.join(binary_run, rel[: -len("usda")] + "usdc")))
    text_bytes = binary_bytes = 0
    for t, b in pairs:
        if not os.path.isfile(b):
            fail(f"{b} missing")
        with open(b, "rb") as fh:
            if fh.read(8) != b"PXR-USDC":
                fail(f"{b} is not a binary (crate) layer")
        lt, lb = Sdf.Layer.FindOrOpen(t), Sdf.Layer.FindOrOpen(b)
        if not lt or not lb:
            fail(f"usd-core did not open {t if not lt else b}")
        st = lt.ExportToString()
        sb = lb.ExportToString().replace(".usdc@", ".usda@")
        if st != sb:
            diff = next(i for i, (x, y) in enumerate(zip(st.splitlines(), sb.splitlines())) if x != y)
            fail(f"{os.path.relpath(b, binary_run)} differs from the text layer at line {diff + 1}: "
                 f"{st.splitlines()[diff][:120]!r} vs {sb.splitlines()[diff][:120]!r}")
        text_bytes += os.path.getsize(t)
        binary_bytes += os.path.getsize(b)
        del lt, lb
    layer_t, layer_b = pairs[1] if len(pairs) > 1 else pairs[0]
    tt, tb = open_time(layer_t), open_time(layer_b)
    print(f"interop: usd-core reads {len(pairs)} binary layers (crate {Usd.GetVersion()}) holding the same scene as "
          f"the text layers; {binary_bytes / 1e6:.2f} MB against {text_bytes / 1e6:.2f} MB of text; "
          f"{os.path.relpath(layer_b, binary_run)} opened with its points read in {tb * 1e3:.1f} ms "
          f"(median of 5) against {tt * 1e3:.1f} ms for the text")


if __name__ == "__main__":
    main()
