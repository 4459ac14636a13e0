#!/usr/bin/env python3
"""brume's layers, read bottom-up (docs/architecture.md; issue #37):

  core (src/core: images, params, records, camera, errors, the registry's
        interface brume/command.hpp)  -- includes no effect, not even through
        another header;
  the engines (src/gpu, src/io, src/diffusion, src/depth);
  effects (src/effects/<family>/: each family's sources, private headers,
        GPU file, GLSL topic and pass shaders in its folder);
  jobs (src/jobs: the list of commands, run, batch, sample) -- above them.

Checks, on the source tree:
  1. the include closure of every file of src/core names no effect header and
     no jobs header (brume/gpu.hpp, the umbrella, counts as every effect's);
  2. batch*, sample* and rerun* live in src/jobs, not in src/core;
  3. fog's symbols (FogParams, run_fog..., GpuFog, fog_...) appear in at most
     three places outside fog's own files and the tests: the list of commands,
     the build lists (the CMakeLists.txt files that name fog's sources, its
     bench and its fuzz target count as one) and one more -- so that an effect
     costs its own files and one line. The LiDAR fog (include/brume/lidar_fog.hpp,
     src/effects/lidar/ (lidar_camera.cpp: the camera's fog profile for its scan),
     its bench, fuzz target and pictures) is fog's by design and
     not counted: its height-layered model takes fog's profiles, their flags
     and their optical-depth integral (issue #41), rather than copying them.
Exit 1 with what is wrong.

  check_layers.py SOURCE_DIR
"""
import os
import re
import sys

EFFECT_HEADERS = {
    "brume/haze.hpp", "brume/aerial.hpp", "brume/aerial_coefficients.hpp", "brume/fog.hpp", "brume/dof.hpp",
    "brume/sky.hpp", "brume/insert.hpp", "brume/chain.hpp", "brume/blur.hpp", "brume/gpu.hpp",
    "brume/gpu_haze.hpp", "brume/gpu_aerial.hpp", "brume/gpu_fog.hpp", "brume/gpu_sky.hpp",
    "effects/fog/fog_fast.hpp",
}
JOBS_HEADERS = {"brume/batch.hpp", "brume/rerun.hpp"}
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)

# Fog's own files: its headers, its folder (maths, pipeline, GPU pass and
# shader), bench and fuzz target (tests are fog's too).
FOG_OWN = re.compile(r"^(include/brume/(gpu_)?fog(_params)?\.hpp|src/effects/fog/[^/]*|bench/bench_fog\.cpp|"
                     r"fuzz/fuzz_fog[^/]*|tests/.*|docs/.*|README\.md|CHANGELOG\.md)$")
LIDAR_FOG = re.compile(r"^(include/brume/lidar_fog\.hpp|src/effects/lidar/[^/]*|bench/bench_lidar_fog\.cpp|"
                       r"fuzz/fuzz_lidar_fog\.cpp|scripts/lidar_picture\.py)$")
FOG_SYMBOL = re.compile(r"\b(FogParams|FogJob|GpuFog|run_fog\w*|fog_\w+)\b")


def resolve(root, name, here):
    for base in (os.path.dirname(here), os.path.join(root, "include"), os.path.join(root, "src")):
        p = os.path.normpath(os.path.join(base, name))
        if os.path.isfile(p):
            return p
    return None  # a generated or system header


def closure(root, path):
    seen, stack, via = set(), [path], {path: None}
    while stack:
        f = stack.pop()
        with open(f, encoding="utf-8", errors="replace") as fh:
            for inc in INCLUDE.findall(fh.read()):
                p = resolve(root, inc, f)
                if p and p not in seen:
                    seen.add(p)
                    via[p] = f
                    stack.append(p)
    return seen, via


def chain(root, via, p):
    out = []
    while p is not None:
        out.append(os.path.relpath(p, root))
        p = via.get(p)
    return " <- ".join(out)


def main():
    root = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else ".")
    errors = []
    forbidden = {os.path.normpath(os.path.join(root, "include" if h.startswith("brume/") else "src", h))
                 for h in EFFECT_HEADERS | JOBS_HEADERS}
    core = os.path.join(root, "src", "core")
    for name in sorted(os.listdir(core)):
        if re.match(r"(batch|sample|rerun)", name):
            errors.append(f"src/core/{name}: the jobs (batch, sample, rerun) live in src/jobs")
        path = os.path.join(core, name)
        seen, via = closure(root, path)
        for p in sorted(seen & forbidden):
            errors.append(f"src/core/{name} includes an effect or jobs header: {chain(root, via, p)}")
    # Fog's symbols outside its own files.
    users, build_lists = [], []
    for d in ("include", "src", "tools", "python", "bench", "fuzz", "study", "scripts", "cmake"):
        for dirpath, _, files in os.walk(os.path.join(root, d)):
            for fn in files:
                p = os.path.join(dirpath, fn)
                rel = os.path.relpath(p, root)
                if FOG_OWN.match(rel) or LIDAR_FOG.match(rel) or fn == "CMakeLists.txt" or \
                        not fn.endswith((".cpp", ".hpp", ".h", ".py", ".sh", ".txt", ".cmake")):
                    continue
                with open(p, encoding="utf-8", errors="replace") as fh:
                    m = FOG_SYMBOL.search(fh.read())
                if m:
                    users.append(f"{rel} ({m.group(0)})")
    for dirpath, _, files in os.walk(root):
        top = os.path.relpath(dirpath, root).split(os.sep)[0]
        if top != "." and top.startswith(("build", ".")):
            continue
        if "CMakeLists.txt" in files:
            with open(os.path.join(dirpath, "CMakeLists.txt"), encoding="utf-8") as fh:
                if re.search(r"\bfog[._]", fh.read()):
                    build_lists.append(os.path.relpath(os.path.join(dirpath, "CMakeLists.txt"), root))
    if build_lists:
        users.append("the build lists (%s)" % ", ".join(sorted(build_lists)))
    if len(users) > 3:
        errors.append("fog's symbols appear in %d places outside fog's own files (at most 3: the list of "
                      "commands, the build lists and one more): %s" % (len(users), ", ".join(users)))
    for e in errors:
        print("check_layers: " + e)
    print(f"check_layers: {len(errors)} problem(s); fog's symbols outside its files: {', '.join(users) or 'none'}")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
