"""Writes brume/_brume.pyi (and the PEP 561 marker py.typed) into the build-tree
package: the stub text comes from the extension, which builds it from the same
parameter tables that make the CLI flags (python/src/module.cpp, stub_text)."""
import os
import sys

pkg_parent = sys.argv[1]
sys.path.insert(0, pkg_parent)
from brume import _brume  # noqa: E402

out = os.path.join(pkg_parent, "brume")
with open(os.path.join(out, "_brume.pyi"), "w", encoding="utf-8") as f:
    f.write(_brume._stub_text())
with open(os.path.join(out, "py.typed"), "w", encoding="utf-8") as f:
    f.write("")
