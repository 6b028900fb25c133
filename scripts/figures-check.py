#!/usr/bin/env python3
"""Which measured figures of the README and docs are older than the code they
measure: for every entry of docs/figures.toml, the commits after the one that
wrote the figure (`measured_at`) that changed the code it depends on (a commit
that only rewords comments there does not count). Exits 1
when any figure is stale (or its sample text is gone from its pages), 0 when
every figure is current. `make figures-check` runs it.

A group with `record = true` is a dated record, not a current figure: a measurement
that cannot be repeated here (a GPU lent for 15 minutes, a run of hours) or one kept for
comparison. It is never stale, but each of its pages must show it labelled: some paragraph
or table (lines between blank lines) holds both its `sample` and its `as_of` (a date or
a commit), so a reader sees how old it is where they read it.

    scripts/figures-check.py            a line per figure, the stale ones with their newer commits
    scripts/figures-check.py --brief    only the stale ones
"""
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def git(*args):
    return subprocess.run(["git", *args], cwd=ROOT, check=True, capture_output=True, text=True).stdout


# What starts a whole-line comment, by file type (`#` in Rust starts an attribute).
COMMENT_PREFIXES = {".rs": ("//", "/*"), ".cpp": ("//", "/*"), ".h": ("//", "/*"), ".hpp": ("//", "/*"),
                    ".toml": ("#",), ".py": ("#",), ".sh": ("#",)}


def changes_code(commit, paths):
    """Whether `commit` changes a line of `paths` that is not blank and not
    wholly a comment (`#` in TOML and scripts; `//`, `///` or a line opening
    `/*` in Rust and C++): a comment cannot change a measured figure, so a
    commit that only rewords one does not make the figures of its file
    stale. A code line with a comment on it counts, and so does every line
    of any other kind of file."""
    diff = git("show", "--format=", "--unified=0", commit, "--", *paths)
    prefixes = ()
    for line in diff.splitlines():
        if line.startswith("+++ ") or line.startswith("--- "):
            name = line[4:]
            if name != "/dev/null":
                prefixes = COMMENT_PREFIXES.get(Path(name).suffix, ())
            continue
        if not line.startswith(("+", "-")):
            continue
        body = line[1:].strip()
        if body and not (prefixes and body.startswith(prefixes)):
            return True
    return False


def main():
    brief = "--brief" in sys.argv[1:]
    figures = tomllib.loads((ROOT / "docs/figures.toml").read_text())["figure"]
    stale = records = 0
    for f in figures:
        if f.get("record"):
            unlabelled = [p for p in f["pages"] if not any(
                f["sample"] in block and f["as_of"] in block
                for block in (ROOT / p).read_text(errors="replace").split("\n\n"))]
            if unlabelled:
                stale += 1
                print(f"STALE {f['id']}: a record whose '{f['sample']}' has no paragraph or table with its date "
                      f"'{f['as_of']}' in {', '.join(unlabelled)}")
            else:
                records += 1
                if not brief:
                    print(f"record {f['id']}: as of {f['as_of']}, labelled on its pages")
            continue
        problems = []
        try:
            git("cat-file", "-e", f["measured_at"] + "^{commit}")
            newer = git("log", "--format=%h %ad %s", "--date=short", f"{f['measured_at']}..HEAD", "--", *f["depends"]).splitlines()
            newer = [line for line in newer if changes_code(line.split()[0], f["depends"])]
        except subprocess.CalledProcessError:
            newer, problems = [], [f"measured_at {f['measured_at']} is not a commit of this repository"]
        missing = [p for p in f["pages"] if f["sample"] not in (ROOT / p).read_text(errors="replace")]
        if missing:
            problems.append(f"'{f['sample']}' is no longer in {', '.join(missing)}")
        if newer:
            problems.append(f"{len(newer)} newer commit(s) touch {', '.join(f['depends'])}")
        if problems:
            stale += 1
            print(f"STALE {f['id']}: {f['what']}")
            for p in problems:
                print(f"    {p}")
            for line in newer[:3]:
                print(f"      {line[:110]}")
            if len(newer) > 3:
                print(f"      ... and {len(newer) - 3} more")
            print(f"    reproduce: {f['command']}")
        elif not brief:
            print(f"ok    {f['id']}: measured at {f['measured_at'][:9]}, code unchanged since")
    print(f"figures-check: {len(figures) - stale - records} figure groups current, "
          f"{records} dated records, {stale} stale")
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
