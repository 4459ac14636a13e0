#!/usr/bin/env python3
"""brume's layers, read bottom-up (docs/architecture.md; issues #37, #53):

  core      src/core: images, params, the camera, errors;
  engines   src/shared, src/gpu, src/io (and its formats), src/diffusion, and
            src/media (brume/medium.hpp: the interface the camera effects and
            the LiDAR scan share; brume/height_profile.hpp, the height profiles
            both take);
  depth     src/depth: sources, conversion, preparation, completion, stereo, fusion;
  pipeline  src/pipeline: the steps every command shares (load, complete,
            prepare, backend, outputs), records, the registry's interface
            (brume/command.hpp), the preview's frames, image comparison;
  commands  src/effects/<family>/ (each family's sources, private headers, GPU
            file, GLSL topic and pass shaders), src/depth/commands (depth's
            own commands);
  jobs      src/jobs: the list of commands, run, batch, sample, view.

Which header is whose comes from the parts' declarations (CMakeLists.txt,
cmake/brume_parts.cmake): a part's private headers are the *.hpp/*.h of its
folder, its public headers those its HEADERS name (generated/part_headers.txt:
every include/brume/*.hpp has one owner, or the configure fails); LAYERS below
maps each part's folder to its layer (a part in no layer fails here).

Checks, on the source tree:
  1. every part's files and public headers reach -- through any include --
     no header of a part of a higher layer (so no file of src/core reaches a
     depth, pipeline, effect or jobs header), but for the includes
     REACHES_UP names with their reasons (core's may reach the engines only;
     a stale entry fails); the umbrella brume/gpu.hpp is the jobs' (it
     includes every effect's passes); a public header (include/brume/)
     reaches no private one (src/: not installed);
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
  5. brume/gpu.hpp, the umbrella kept by hand, includes every public
     brume/gpu_*.hpp.
Exit 1 with what is wrong.

  check_layers.py SOURCE_DIR GENERATED_DIR   (GENERATED_DIR: the build's generated/)
"""
import os
import re
import sys

# Bottom-up; a part's folder lies in the layer of its longest matching prefix.
LAYERS = [
    ("core", ("src/core",)),
    ("engines", ("src/shared", "src/gpu", "src/io", "src/diffusion", "src/media")),
    ("depth", ("src/depth",)),
    ("pipeline", ("src/pipeline",)),
    ("commands", ("src/effects", "src/depth/commands")),
    ("jobs", ("src/jobs",)),
]
# The includes that still reach a layer above, each with its reason: the name
# tables and record blocks of the engines' and depth's own types are declared
# in the pipeline layer's headers (brume/pipeline.hpp, brume/record.hpp).
# Keyed by the file and its direct include; an entry that no longer reaches a
# layer above fails the check (remove it), and core's may reach the engines
# only, never depth or above.
REACHES_UP = {
    ("src/core/camera.cpp", "brume/io.hpp"):
        "a --view-matrix file read (read_input_file) and hashed for the record (sha256_file) through io",
    ("src/io/codec.cpp", "brume/pipeline.hpp"): "run_phases(): loading the codec is timed in the run's read",
    ("src/depth/source.cpp", "brume/record.hpp"): "file_record: the depth file's record block",
    ("src/depth/stereo.cpp", "brume/record.hpp"): "file_record: the right view's record block",
}
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)

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
                if p and p not in seen and p != path:
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


def layer_of(folder):
    best = None
    for rank, (name, prefixes) in enumerate(LAYERS):
        for pre in prefixes:
            if (folder == pre or folder.startswith(pre + "/")) and (best is None or len(pre) > best[2]):
                best = (rank, name, len(pre))
    return best


def read_parts(root, gen):
    """[(name, folder, layer rank, layer name, [public header paths])] from the configure's lists."""
    with open(os.path.join(gen, "parts.txt"), encoding="utf-8") as fh:
        folders = [line.split() for line in fh if line.strip()]
    headers = {}
    with open(os.path.join(gen, "part_headers.txt"), encoding="utf-8") as fh:
        for line in fh:
            words = line.split()
            if words:
                headers[words[0]] = [os.path.join(root, "include", h) for h in words[1:]]
    parts, errors = [], []
    for name, folder in folders:
        layer = layer_of(folder)
        if layer is None:
            errors.append(f"part {name} ({folder}) lies in no layer: add its folder to LAYERS in tests/check_layers.py "
                          "and to docs/architecture.md's diagram")
            continue
        parts.append((name, folder, layer[0], layer[1], headers.get(name, [])))
    return parts, errors


def main():
    root = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else ".")
    gen = os.path.abspath(sys.argv[2] if len(sys.argv) > 2 else os.path.join(root, "build", "generated"))
    parts, errors = read_parts(root, gen)
    # Every header's part and layer: a part's public headers and its folder's own.
    owner = {}
    files_of = {}
    for name, folder, rank, layer, public in parts:
        d = os.path.join(root, folder)
        own = sorted(os.path.join(d, f) for f in os.listdir(d) if os.path.isfile(os.path.join(d, f)))
        for h in public + [f for f in own if f.endswith((".hpp", ".h"))]:
            owner[os.path.normpath(h)] = (name, rank, layer)
        files_of[name] = public + [f for f in own if f.endswith((".cpp", ".hpp", ".h"))]
    inc = os.path.join(root, "include", "brume")
    for h in sorted(os.listdir(inc)):
        if os.path.normpath(os.path.join(inc, h)) not in owner:
            errors.append(f"include/brume/{h} is no part's: name it in its part's HEADERS (CMakeLists.txt) and "
                          "configure again")
    # 5. The umbrella brume/gpu.hpp, a list by hand (a header cannot glob):
    # it includes every public GPU header (gpu_<family>.hpp, gpu_context.hpp).
    with open(os.path.join(inc, "gpu.hpp"), encoding="utf-8") as fh:
        umbrella = set(INCLUDE.findall(fh.read()))
    for h in sorted(os.listdir(inc)):
        if re.match(r"gpu_\w+\.hpp$", h) and f"brume/{h}" not in umbrella:
            errors.append(f"include/brume/gpu.hpp, the umbrella of every effect's GPU passes, does not include "
                          f"brume/{h}: add it")
    used = set()
    for name, folder, rank, layer, public in parts:
        for path in files_of[name]:
            rel = os.path.relpath(path, root)
            seen, via = closure(root, path)
            if rel.startswith("include" + os.sep):
                for p in sorted(seen):
                    if not p.startswith(os.path.join(root, "include") + os.sep):
                        errors.append(f"{rel} reaches a private header, which is not installed: {chain(root, via, p)}")
            for p in sorted(seen):
                o = owner.get(p)
                if not o or o[1] <= rank:
                    continue
                hop = p
                while via[hop] != path:
                    hop = via[hop]
                key = (rel, os.path.relpath(hop, os.path.join(root, "include")))
                if key in REACHES_UP and (layer != "core" or o[2] == "engines"):
                    used.add(key)
                    continue
                errors.append(f"{rel} ({layer}) reaches a header of {o[0]} ({o[2]}, a layer above): "
                              f"{chain(root, via, p)}")
    for key in sorted(set(REACHES_UP) - used):
        errors.append(f"{key[0]} no longer reaches a layer above through {key[1]}: remove it from REACHES_UP")
    core = os.path.join(root, "src", "core")
    for name in sorted(os.listdir(core)):
        if re.match(r"(batch|sample|rerun)", name):
            errors.append(f"src/core/{name}: the jobs (batch, sample, rerun) live in src/jobs")
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
    print(f"check_layers: {len(parts)} parts in {len(LAYERS)} layers, {len(owner)} headers; {len(errors)} problem(s); "
          f"fog's symbols outside its files: {', '.join(users) or 'none'}; the LiDAR fog's {len(lidar_names)} names checked")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
