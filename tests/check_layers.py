#!/usr/bin/env python3
"""brume's layers, read bottom-up (docs/architecture.md; issues #37, #53):

  core (src/core: images, params, records, camera, errors, the registry's
        interface brume/command.hpp)  -- includes no effect, not even through
        another header;
  the engines (src/gpu, src/io, src/diffusion, src/depth) and the media
        (src/media: brume/medium.hpp, the interface the camera effects and
        the LiDAR scan share, and brume/height_profile.hpp, the height
        profiles both take) -- the media include no effect either;
  effects (src/effects/<family>/: each family's sources, private headers,
        GPU file, GLSL topic and pass shaders in its folder);
  jobs (src/jobs: the list of commands, run, batch, sample) -- above them.

Checks, on the source tree:
  1. the include closure of every file of src/core and src/media names no
     effect header and no jobs header (brume/gpu.hpp, the umbrella, counts as
     every effect's);
  2. batch*, sample* and rerun* live in src/jobs, not in src/core;
  3. fog's symbols (FogParams, run_fog..., GpuFog, fog_...) appear in at most
     three files outside fog's own files and the tests, the build lists (the
     CMakeLists.txt files that name fog's sources, its bench and its fuzz
     target) counting as one -- so that an effect costs its own files and
     one line. The media (src/media, brume/medium.hpp,
     brume/height_profile.hpp) are a part of their own and counted like any
     other; the LiDAR fog takes the height profiles from them, not from fog;
  4. the LiDAR fog's types and functions (every name its public header
     include/brume/lidar_fog.hpp declares) appear in no C++, CMake or Python
     file outside its family's folder (src/effects/lidar/), that header, its
     Python module (python/brume/lidar.py), its bench, its fuzz target and
     the tests -- except one line of the list of commands
     (src/jobs/commands.cpp) and one build line (CMakeLists.txt): a camera
     effect reaches a scan's medium through brume/medium.hpp only.
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
    "effects/fog/fog_fast.hpp", "brume/lidar_fog.hpp", "brume/lidar_camera.hpp",
}
JOBS_HEADERS = {"brume/batch.hpp", "brume/rerun.hpp"}
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)

# Fog's own files: its headers, its folder (maths, pipeline, GPU pass and
# shader), bench and fuzz target (tests are fog's too).
FOG_OWN = re.compile(r"^(include/brume/(gpu_)?fog(_params)?\.hpp|src/effects/fog/[^/]*|bench/bench_fog\.cpp|"
                     r"fuzz/fuzz_fog[^/]*|tests/.*|docs/.*|README\.md|CHANGELOG\.md)$")
# The LiDAR fog's own files, and where else its names may stand.
LIDAR_OWN = re.compile(r"^(include/brume/lidar_fog\.hpp|src/effects/lidar/[^/]*|python/brume/lidar\.py|"
                       r"bench/bench_lidar_fog\.cpp|bench/CMakeLists\.txt|fuzz/fuzz_lidar_fog[^/]*|"
                       r"fuzz/CMakeLists\.txt|tests/.*|python/tests/.*)$")
LIDAR_ONE_LINE = {"src/jobs/commands.cpp": "the list of commands", "CMakeLists.txt": "the build line"}
LIDAR_HEADER = "include/brume/lidar_fog.hpp"
FOG_SYMBOL = re.compile(r"\b(FogParams|FogJob|GpuFog|run_fog\w*|fog_\w+)\b")
# What a public header declares at namespace scope: types, functions, constants.
DECLARED = re.compile(r"^(?:struct|class|enum class)\s+(\w+)|"
                      r"^(?:(?:constexpr|const|inline|static)\s+)?[\w:<>,]+[&*]?\s+[&*]?(\w+)\s*(?:\(|=)", re.M)


def declared_names(path):
    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    names = set()
    for m in DECLARED.finditer(text):
        name = m.group(1) or m.group(2)
        if name and name not in ("operator", "brume"):
            names.add(name)
    return names


def source_files(root):
    """Every C++, CMake and Python file of the tree (not the build folders)."""
    for dirpath, dirs, files in os.walk(root):
        rel_dir = os.path.relpath(dirpath, root)
        top = rel_dir.split(os.sep)[0]
        if top != "." and top.startswith(("build", ".")):
            dirs[:] = []
            continue
        for fn in files:
            if fn.endswith((".cpp", ".hpp", ".h", ".py", ".cmake")) or fn == "CMakeLists.txt":
                p = os.path.join(dirpath, fn)
                yield os.path.relpath(p, root), p



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
    for layer in ("core", "media"):
        folder = os.path.join(root, "src", layer)
        files = [os.path.join(folder, n) for n in sorted(os.listdir(folder))]
        if layer == "media":
            files += [os.path.join(root, "include", "brume", h) for h in ("medium.hpp", "height_profile.hpp")]
        for path in files:
            seen, via = closure(root, path)
            for p in sorted(seen & forbidden):
                errors.append(f"{os.path.relpath(path, root)} includes an effect or jobs header: "
                              f"{chain(root, via, p)}")
    # Fog's symbols outside its own files.
    users, build_lists = [], []
    for d in ("include", "src", "tools", "python", "bench", "fuzz", "study", "scripts", "cmake"):
        for dirpath, _, files in os.walk(os.path.join(root, d)):
            for fn in files:
                p = os.path.join(dirpath, fn)
                rel = os.path.relpath(p, root)
                if FOG_OWN.match(rel) or fn == "CMakeLists.txt" or \
                        not fn.endswith((".cpp", ".hpp", ".h", ".py", ".sh", ".txt", ".cmake")):
                    continue
                with open(p, encoding="utf-8", errors="replace") as fh:
                    found = set(FOG_SYMBOL.findall(fh.read()))
                if found:
                    users.append(f"{rel} ({sorted(found)[0]})")
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
        errors.append("fog's symbols appear in %d files outside fog's own files (at most 3, the build lists "
                      "counting as one): %s" % (len(users), ", ".join(users)))
    # The LiDAR fog's names outside its own files.
    lidar_names = declared_names(os.path.join(root, LIDAR_HEADER))
    lidar_word = re.compile(r"\b(%s)\b|brume/lidar_fog\.hpp" % "|".join(sorted(lidar_names, key=len, reverse=True)))
    lidar_users = []
    for rel, p in source_files(root):
        if LIDAR_OWN.match(rel):
            continue
        with open(p, encoding="utf-8", errors="replace") as fh:
            lines = [(i + 1, ln) for i, ln in enumerate(fh.read().splitlines()) if lidar_word.search(ln)]
        if not lines or (rel in LIDAR_ONE_LINE and len(lines) == 1):
            continue
        lidar_users.append(f"{rel}:{lines[0][0]} ({lidar_word.search(lines[0][1]).group(0)}"
                           f"{', %d lines' % len(lines) if len(lines) > 1 else ''})")
    if lidar_users:
        errors.append("the LiDAR fog's names appear outside its folder, its header, its Python module, bench, fuzz "
                      "and tests (only one line of src/jobs/commands.cpp and one of CMakeLists.txt may name it; a "
                      "camera effect reaches a scan's medium through brume/medium.hpp): " + ", ".join(lidar_users))
    for e in errors:
        print("check_layers: " + e)
    print(f"check_layers: {len(errors)} problem(s); fog's symbols outside its files: {', '.join(users) or 'none'}; "
          f"the LiDAR fog's {len(lidar_names)} names checked")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
