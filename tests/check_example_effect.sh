#!/usr/bin/env bash
# docs/architecture.md's "Adding an effect", executed (issue #53; ctest
# example_effect_builds_from_its_files): the example effect of examples/effect/
# (brume absorb: its public header, its folder with a GLSL topic, a CPU path
# and a pipeline, a test file) is copied into a scratch copy of the tree with
# the one list line and the one build line the checklist names and nothing
# else; the copy is configured (no Python module, no benchmarks), brume_cli and
# brume_tests are built, the CLI reference is regenerated, and the command-list
# tests, the example's own tests, the layer check, the parts check and the
# reference check run there. A step the checklist does not name that a new
# effect turns out to need fails here.
#   check_example_effect.sh REPO WORK
set -euo pipefail
repo=$(cd "$1" && pwd)
work=$2
tree=$work/tree
example=$repo/examples/effect
t0=$(date +%s)
rm -rf "$work"
mkdir -p "$tree"

# The tree as it is checked out: tracked files and new ones git does not
# ignore, without build folders; a plain copy where there is no git checkout.
if git -C "$repo" rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  (cd "$repo" && git ls-files -z --cached --others --exclude-standard |
     tar --null --files-from=- --ignore-failed-read -cf - 2>/dev/null) | tar -xf - -C "$tree"
else
  (cd "$repo" && tar --exclude='./build*' --exclude='./.git' -cf - .) | tar -xf - -C "$tree"
fi
# Nothing of the example may be in the tree already.
if [ -e "$tree/include/brume/absorb.hpp" ] || [ -e "$tree/src/effects/absorb" ]; then
  echo "check_example_effect: the tree already has an 'absorb' effect; the example must add it" >&2
  exit 1
fi

# 1. Its own files, nothing else.
cp -R "$example/include" "$example/src" "$example/tests" "$tree/"
# 2. One line in the list, before the last command of --help.
list=$tree/src/jobs/commands.cpp
grep -q '^  X(view_command)$' "$list" || {
  echo "check_example_effect: src/jobs/commands.cpp has no line '  X(view_command)' to add the example before;" \
       "update this script's anchor and the list line of docs/architecture.md" >&2
  exit 1
}
sed -i 's/^  X(view_command)$/  X(absorb_command) \\\n  X(view_command)/' "$list"
# 3. One build line, after the last effect family's.
cml=$tree/CMakeLists.txt
grep -q '^brume_part(blur src/effects/blur' "$cml" || {
  echo "check_example_effect: CMakeLists.txt has no 'brume_part(blur src/effects/blur' line to add the example after;" \
       "update this script's anchor" >&2
  exit 1
}
sed -i '/^brume_part(blur src\/effects\/blur/a brume_part(absorb src/effects/absorb HEADERS absorb.hpp TESTS test_absorb.cpp)' "$cml"
[ "$(git -C "$repo" diff --no-index --numstat "$repo/src/jobs/commands.cpp" "$list" | cut -f1,2)" = "$(printf '1\t0')" ]
[ "$(git -C "$repo" diff --no-index --numstat "$repo/CMakeLists.txt" "$cml" | cut -f1,2)" = "$(printf '1\t0')" ]

# Configure and build. -O0 without debug information: these tests check the
# wiring, not speed, and an unoptimised build of the whole tree takes about
# half of a Release one's time. ccache, when present, keeps a rerun short.
launcher=()
if command -v ccache >/dev/null; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  export CCACHE_BASEDIR=$tree CCACHE_NOHASHDIR=1
fi
cmake -S "$tree" -B "$tree/build" -DCMAKE_BUILD_TYPE=Debug "-DCMAKE_CXX_FLAGS_DEBUG=-O0" \
  -DCMAKE_UNITY_BUILD=ON -DBRUME_PYTHON=OFF -DBRUME_BUILD_BENCH=OFF "${launcher[@]}" >"$work/configure.log" 2>&1 || {
  tail -40 "$work/configure.log" >&2
  exit 1
}
grep -q 'absorb_math.glsl' "$tree/build/generated/shared/topics_cpp.inc" || {
  echo "check_example_effect: the example's GLSL topic is not among the generated topics" >&2
  exit 1
}
cmake --build "$tree/build" -j"$(nproc)" --target brume_cli brume_tests >"$work/build.log" 2>&1 || {
  grep -E 'error|Error' "$work/build.log" | head -40 >&2
  exit 1
}
t1=$(date +%s)

# The reference, regenerated as the checklist says; it then holds the page.
"$tree/build/brume" reference --out-dir "$tree/docs/cli"
grep -q '`brume absorb`' "$tree/docs/cli/README.md"
[ -f "$tree/docs/cli/absorb.md" ]

# The list's tests over every command (the example's included), its own tests.
"$tree/build/tests/brume_tests" --gtest_brief=1 \
  --gtest_filter='Commands.*:CommandsInFiles.*:Sample.*:Absorb.*:AbsorbCli.*' 2>&1 | tail -20
n=$("$tree/build/tests/brume_tests" --gtest_list_tests --gtest_filter='Absorb.*:AbsorbCli.*' | grep -c '^  ')
[ "$n" -ge 3 ] || { echo "check_example_effect: the example's own tests did not join brume_tests ($n cases)" >&2; exit 1; }
# The layer check, the parts check and the reference check on the copy.
ctest --test-dir "$tree/build" --output-on-failure \
  -R '^(layers_core_includes_no_effect|build_parts_are_folders|docs_cli_reference_is_current)$' | tail -6
echo "check_example_effect: built in $((t1 - t0)) s, checked in $(($(date +%s) - t1)) s"
# Passed: the copy's 270 MB go (its logs stay; a failure keeps everything).
rm -rf "$tree"
