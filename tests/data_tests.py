#!/usr/bin/env python3
"""Which tests read the real data (ctest label `data`, tests/labels.cmake).

gtest: prints the GoogleTest cases (`Suite.Name`, one a line) of the given
C++ files whose body uses the data helpers of tests/test_util.hpp (data_dir,
data_path, have_data, BRUME_REQUIRE_DATA), directly or through what the same
file defines with them: a function, a constant, a macro, a fixture whose
set-up reads the data (a TEST_F/TEST_P on it uses it), or a member function
of a fixture (a test that calls it uses it). Names found that way count as
data helpers in turn until nothing changes (a fixpoint); what test_util.hpp
itself defines with them (middlebury2005, ...) counts in every file. The
match is by name, so a helper's name used for something else in the same
file labels a test too many: the label may hold a test that does not need
the data (it then runs once more in CI), never miss one that does.

pytest: prints the python/tests files (one a line) that name conftest.py's
`data_dir` fixture or its data_folder() (a test, a fixture or a mark).

Fails (exit 1, naming the problem) when it finds fewer than --min tests or
files: a parse that silently labels nothing is a failure, not a pass.

Usage: data_tests.py gtest [--util HEADER]... --min N FILE...
       data_tests.py pytest --min N FILE...
       data_tests.py self-test tests/test_util.hpp   (the parser on a sample)
"""
import argparse
import re
import sys

SEEDS = {"data_dir", "data_path", "have_data", "BRUME_REQUIRE_DATA"}
TEST_MACROS = ("TEST", "TEST_F", "TEST_P", "TYPED_TEST", "TYPED_TEST_P")
# Members of a fixture that run for every test on it.
SETUP_MEMBERS = {"SetUp", "SetUpTestSuite", "SetUpTestCase", "TearDown", "TearDownTestSuite"}
IDENT = re.compile(r"[A-Za-z_]\w*")
KEYWORDS = {"const", "constexpr", "static", "inline", "override", "noexcept", "final", "volatile", "mutable",
            "virtual", "explicit", "return", "auto", "void", "int", "double", "float", "bool", "char", "unsigned",
            "std", "public", "private", "protected", "template", "typename", "namespace", "using", "operator"}


def strip(text):
    """The text with comments, string and character literals blanked (their
    characters replaced, newlines kept), so that braces and names in them
    do not count."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == "R" and text.startswith('R"', i) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            m = re.match(r'R"([^(\s]*)\(', text[i:])
            if not m:
                out.append(c)
                i += 1
                continue
            end = ")" + m.group(1) + '"'
            j = text.find(end, i + m.end())
            j = n if j < 0 else j + len(end)
            out.append('""' + re.sub(r"[^\n]", " ", text[i + 2:j]))
            i = j
        elif c in "\"'":
            if c == "'" and i > 0 and text[i - 1].isalnum():  # a digit separator (1'000)
                out.append(" ")
                i += 1
                continue
            j = i + 1
            while j < n and text[j] != c and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            out.append(c + " " * max(0, min(j, n) - i - 1) + (c if j < n else ""))
            i = j + 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def macros(text):
    """#define'd names with their bodies, and the text with every
    preprocessor line (and its continuations) blanked."""
    defs, lines, directive = [], text.split("\n"), None
    for k, line in enumerate(lines):
        if directive is None and not line.lstrip().startswith("#"):
            continue
        if directive is None:
            m = re.match(r"\s*#\s*define\s+(\w+)(.*)", line)
            directive = [m.group(1), m.group(2)] if m else ["", ""]
            if m:
                defs.append(directive)
        else:
            directive[1] += " " + line
        lines[k] = ""
        if not line.rstrip().endswith("\\"):
            directive = None
    return [(name, body) for name, body in defs], "\n".join(lines)


def items(text):
    """The top-level items of `text` (namespaces opened, not counted): a
    list of (header, body) where body is the text between the item's
    outermost braces ("" for a declaration ending in ';')."""
    out, header, i, n = [], [], 0, len(text)
    while i < n:
        c = text[i]
        if c == ";":
            h = "".join(header).strip()
            if h:
                out.append((h, ""))
            header = []
            i += 1
        elif c == "{":
            h = "".join(header).strip()
            if re.search(r"(^|\s)namespace(\s+[\w:]+)?\s*$", h) or re.fullmatch(r'extern\s*"\s*"', h):
                header = []  # a namespace's contents are top-level items
                i += 1
                continue
            depth, j = 1, i + 1
            while j < n and depth:
                depth += {"{": 1, "}": -1}.get(text[j], 0)
                j += 1
            out.append((h, text[i + 1:j - 1]))
            header = []
            i = j
        elif c == "}":  # a namespace's close
            header = []
            i += 1
        else:
            header.append(c)
            i += 1
    return out


def names_of(header):
    """The names an item's header defines (possibly none)."""
    h = re.sub(r"\b(public|private|protected)\s*:", " ", header)
    h = re.sub(r"template\s*<[^{;]*?>\s*(?=\w)", " ", h)
    m = re.search(r"\b(class|struct|union|enum(\s+class)?)\s+(\w+)", h)
    if m and "(" not in h[:m.start()]:
        return [m.group(3)]
    # a variable with an initialiser: the name before the first top-level '='
    depth = 0
    for k, ch in enumerate(h):
        if ch in "(<[":
            depth += 1
        elif ch in ")>]":
            depth -= 1
        elif ch == "=" and depth == 0 and h[k + 1:k + 2] != "=" and h[k - 1:k] not in "!<>=":
            ids = [w for w in IDENT.findall(h[:k]) if w not in KEYWORDS]
            return ids[-1:] if not re.search(r"\boperator\s*$", h[:k]) else []
    # a function: the name before the parameter list's '('
    m = re.search(r"(~?\w+)\s*\(", h)
    if m and m.group(1) not in KEYWORDS:
        return [m.group(1)]
    if "(" in h:  # an operator, a macro call: nothing named
        return []
    # a declaration without initialiser: the last name (int x; const char* kPath[];)
    ids = [w for w in IDENT.findall(h) if w not in KEYWORDS]
    return ids[-1:]


def ids(text):
    return set(IDENT.findall(text))


def reaching(units, names):
    """The names that reach data: `names`, and to a fixpoint every unit
    (names, identifiers used) whose identifiers include one of them."""
    names = set(names)
    changed = True
    while changed:
        changed = False
        for defined, used in units:
            if used & names and not set(defined) <= names:
                names |= set(defined)
                changed = True
    return names


def gtest_cases(path, helpers):
    """(cases using the data, all cases) of one C++ file."""
    defs, text = macros(strip(open(path, encoding="utf-8").read()))
    units = []  # (names defined, identifiers used)
    tests = []  # (Suite.Name, identifiers used)
    for name, body in defs:
        units.append(([name], ids(body)))
    for header, body in items(text):
        m = re.match(r"(\w+)\s*\(\s*(\w+)\s*,\s*(\w+)\s*\)\s*$", header)
        if m and m.group(1) in TEST_MACROS:
            used = ids(body)
            if m.group(1) != "TEST":
                used.add(m.group(2))  # the fixture
            tests.append((f"{m.group(2)}.{m.group(3)}", used))
            continue
        names = names_of(header)
        if re.search(r"\b(class|struct)\s+\w+", header) and body:
            # A class: its set-up (constructor, SetUp, members' initialisers)
            # and its base classes make the class a data helper; its other
            # member functions are helpers of their own name.
            cls = names[0] if names else ""
            whole = ids(re.sub(r"\b(class|struct)\s+\w+", " ", header))  # the bases
            for mh, mb in items(body):
                mnames = names_of(mh)
                is_func = bool(mb) and "(" in mh and "=" not in mh.split("(")[0]
                if not is_func or not mnames or mnames[0] in SETUP_MEMBERS or mnames[0] in (cls, "~" + cls):
                    whole |= ids(mh) | ids(mb)
                else:
                    units.append((mnames, ids(mh) | ids(mb)))
            units.append((names, whole))
        elif names:
            units.append((names, ids(header) | ids(body)))
    data = reaching(units, set(helpers))
    return [name for name, used in tests if used & data], [name for name, _ in tests]


# The self-test (ctest data_label_derivation): each way of reaching the data,
# and things that only look like it.
SELF_TEST = r"""
namespace {
const char* kPath = "x/y.bin";  // data_path in a comment does not count
std::string helper_a() { return data_path(kPath); }
std::string helper_b(int n = 2) { return helper_a() + "z{"; }
#define NEED_X() \
  BRUME_REQUIRE_DATA("x")
const std::string kFile = data_path("q");
auto lam = [](int) { return have_data("r"); };
}  // namespace
class DataFixture : public ScratchDirTest {
 protected:
  void SetUp() override { img = data_path("a"); }
  std::string img;
};
class Derived : public DataFixture {};
class Mixed : public ::testing::Test {
 protected:
  std::string art() const { return data_path("art"); }
  int synthetic() const { return 3; }
};
TEST(S, Direct) { BRUME_REQUIRE_DATA("a"); }
TEST(S, ViaChain) { auto s = helper_b(); }
TEST(S, ViaMacro) { NEED_X(); }
TEST(S, ViaConst) { auto s = kFile; }
TEST(S, ViaLambda) { lam(1); }
TEST(S, Pure) { const char* s = "data_path(\"x\")"; char c = '{'; int k = 1'000; }
TEST_F(DataFixture, ViaFixture) {}
TEST_F(Derived, ViaBase) {}
TEST_F(Mixed, UsesMember) { art(); }
TEST_F(Mixed, DoesNot) { synthetic(); }
TEST(S, RawString) { auto r = R"x(data_path( { )x"; }
TEST(S, AfterRaw) { middlebury2005("Art"); }
TEST_P(Param, ViaDir) { auto d = data_dir(); }
"""
SELF_TEST_DATA = {"S.Direct", "S.ViaChain", "S.ViaMacro", "S.ViaConst", "S.ViaLambda", "DataFixture.ViaFixture",
                  "Derived.ViaBase", "Mixed.UsesMember", "S.AfterRaw", "Param.ViaDir"}


def self_test(util):
    import os
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        f = os.path.join(d, "t.cpp")
        with open(f, "w", encoding="utf-8") as out:
            out.write(SELF_TEST)
        sys.argv = [sys.argv[0], "gtest", "--min", "1", "--util", util, f]
        import contextlib
        import io
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            rc = main()
    got = set(buf.getvalue().split())
    if rc != 0 or got != SELF_TEST_DATA:
        print(f"data_tests.py self-test: labelled {sorted(got)}, wanted {sorted(SELF_TEST_DATA)}; missing "
              f"{sorted(SELF_TEST_DATA - got)}, extra {sorted(got - SELF_TEST_DATA)}", file=sys.stderr)
        return 1
    print(f"data_tests.py self-test: the {len(SELF_TEST_DATA)} data cases of {len(re.findall(r'^TEST', SELF_TEST, re.M))} found")
    return 0


def main():
    if sys.argv[1:2] == ["self-test"]:
        return self_test(sys.argv[2])
    ap = argparse.ArgumentParser()
    ap.add_argument("kind", choices=("gtest", "pytest"))
    ap.add_argument("--util", action="append", default=[],
                    help="a header of helpers every file may use (tests/test_util.hpp; repeatable)")
    ap.add_argument("--min", type=int, required=True, help="fail when fewer are found")
    ap.add_argument("files", nargs="+")
    a = ap.parse_args()
    found, total = [], 0
    if a.kind == "gtest":
        helpers = set(SEEDS)
        # What the headers define with the seeds (test_util.hpp's
        # middlebury2005, ...): their items read as one file's, with no tests.
        units = []
        for util in a.util:
            defs, text = macros(strip(open(util, encoding="utf-8").read()))
            units += [([n], ids(b)) for n, b in defs]
            units += [(names_of(h), ids(h) | ids(b)) for h, b in items(text) if names_of(h)]
        helpers = reaching(units, helpers)
        for f in a.files:
            data, every = gtest_cases(f, helpers)
            found += data
            total += len(every)
    else:
        for f in a.files:
            text = open(f, encoding="utf-8").read()
            total += 1
            if re.search(r"\b(data_dir|data_folder)\b", text):
                found.append(f)
    if len(found) < a.min:
        print(f"data_tests.py: found {len(found)} {a.kind} {'cases' if a.kind == 'gtest' else 'files'} that use "
              f"the data (of {total}), expected at least {a.min}: the derivation of the ctest label `data` is "
              f"broken (or --min is out of date)", file=sys.stderr)
        return 1
    print("\n".join(sorted(set(found))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
