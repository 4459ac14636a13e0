#!/usr/bin/env python3
"""Every runnable example of the README and docs/ runs (ctest docs_examples).

Each fenced ```sh or ```bash block of README.md and docs/*.md runs as written,
with `bash -e`, and each ```python block with the module's interpreter
(PYTHONPATH=build/python), in one scratch folder that holds:
  demo-out/   the demo scene (`brume demo --out-dir demo-out`),
  build       a link to the build tree (`./build/brume`, build/python),
  docs, examples  links to the repository's (their scripts),
  renders     a link to tests/renders (the Blender renders docs/renderers.md uses),
and beside it `../shared/data`, a link to the data folder (the environment
variable BRUME_DATA_DIR when set, else --data). Blocks run in file
order, each file's blocks in the same folder, so a block may use what an
earlier one of its page wrote. A block passes when it exits 0 and every file
it names after --out, --out-dir, --record, --json, --plot or --manifest
exists afterwards. Blocks that start with the line `# illustrative` (set-up
commands, synopses, files a user would bring) are not run; blocks that
read ../shared, or use the Python module (python blocks, or build/python), are skipped with a message when
the data is absent (the folder is missing or empty, or lacks a ../shared/data/... path the block names) or
the module not built. `python3` is --python (the
interpreter the module was built for).
"""
import argparse
import glob
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time

FENCE = re.compile(r"^```(sh|bash|python)\n(.*?)^```", re.S | re.M)
NAMED = ("--out", "--out-dir", "--record", "--json", "--plot", "--manifest")
DATA_PATH = re.compile(r"\.\./shared/data/[^\s\"'$;|&),`]+")


def blocks(repo):
    files = [os.path.join(repo, "README.md")] + sorted(glob.glob(os.path.join(repo, "docs", "*.md")))
    for f in files:
        text = open(f, encoding="utf-8").read()
        for m in FENCE.finditer(text):
            line = text[: m.start()].count("\n") + 1
            yield os.path.relpath(f, repo), line, m.group(1), m.group(2)


def named_outputs(body):
    """The files a block says it writes (the argument after each NAMED flag)."""
    words = []
    for line in body.replace("\\\n", " ").splitlines():
        line = line.split(" #", 1)[0]
        if line.strip().startswith("#"):
            continue
        try:
            words += shlex.split(line)
        except ValueError:
            pass
    out = []
    for i, w in enumerate(words[:-1]):
        if w in NAMED and words[i + 1] != "-":
            out.append(words[i + 1])
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repo", required=True)
    ap.add_argument("--build", required=True, help="the build tree (holds brume and python/)")
    ap.add_argument("--data", required=True,
                    help="the data folder (../shared/data); the environment variable BRUME_DATA_DIR overrides it")
    ap.add_argument("--python", default="/usr/bin/python3", help="the python3 the examples run")
    ap.add_argument("--only", default="", help="run only the blocks of files whose path contains this")
    a = ap.parse_args()
    a.data = os.environ.get("BRUME_DATA_DIR") or a.data
    a.repo, a.build, a.data = (os.path.abspath(x) for x in (a.repo, a.build, a.data))
    brume = os.path.join(a.build, "brume")
    have_python = os.path.isdir(os.path.join(a.build, "python", "brume"))
    have_data = os.path.isdir(a.data) and bool(os.listdir(a.data))
    root = tempfile.mkdtemp(prefix="brume_docs_")
    work = os.path.join(root, "work")
    os.makedirs(work)
    if have_data:
        # ../shared/data is the data folder, whatever its own name
        os.makedirs(os.path.join(root, "shared"))
        os.symlink(a.data, os.path.join(root, "shared", "data"))
    # `python3` in the examples is the interpreter the module was built for.
    bindir = os.path.join(root, "bin")
    os.makedirs(bindir)
    os.symlink(a.python, os.path.join(bindir, "python3"))
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([a.build, bindir, env.get("PATH", "")])
    failures, ran, skipped = [], 0, 0
    try:
        subprocess.run([brume, "demo", "--out-dir", "demo-out", "--width", "800", "--height", "560"], cwd=work, env=env, check=True,
                       stdout=subprocess.DEVNULL)
        for name, target in (("build", a.build), ("docs", os.path.join(a.repo, "docs")),
                             ("examples", os.path.join(a.repo, "examples")),
                             ("renders", os.path.join(a.repo, "tests", "renders"))):
            os.symlink(os.path.abspath(target), os.path.join(work, name))
        penv = dict(env, PYTHONPATH=os.path.join(work, "build", "python"))
        for f, line, lang, body in blocks(a.repo):
            where = f"{f}:{line}"
            if a.only and a.only not in f:
                continue
            if body.lstrip().startswith("# illustrative"):
                continue
            if "../shared" in body:
                lacking = [] if have_data else [a.data]
                lacking += [p for p in DATA_PATH.findall(body) if have_data and not os.path.exists(
                    os.path.join(a.data, p[len("../shared/data/"):]))]
                if lacking:
                    print(f"skip {where}: needs the data folder (BRUME_DATA_DIR, else ../shared/data), "
                          f"absent or empty or without {lacking[0]}")
                    skipped += 1
                    continue
            if (lang == "python" or "build/python" in body) and not have_python:
                print(f"skip {where}: needs the Python module (build/python), not built")
                skipped += 1
                continue
            t0 = time.monotonic()
            cmd = [a.python, "-c", body] if lang == "python" else ["bash", "-e", "-o", "pipefail", "-c", body]
            r = subprocess.run(cmd, cwd=work, env=penv if lang == "python" else env,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=900)
            ran += 1
            missing = [p for p in named_outputs(body) if not os.path.exists(os.path.join(work, p))]
            status = "ok" if r.returncode == 0 and not missing else "FAILED"
            print(f"{status} {where} ({time.monotonic() - t0:.1f} s)")
            if status != "ok":
                tail = r.stdout.decode("utf-8", "replace")[-3000:]
                why = f"exit {r.returncode}" if r.returncode else f"did not write {', '.join(missing)}"
                failures.append(f"{where}: {why}\n{tail}")
    finally:
        shutil.rmtree(root, ignore_errors=True)
    print(f"docs examples: {ran} run, {skipped} skipped, {len(failures)} failed")
    for fl in failures:
        print("----\n" + fl)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
