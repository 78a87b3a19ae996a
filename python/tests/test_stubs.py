"""The type stubs of the compiled core name exactly what it defines."""

import ast
from pathlib import Path

import edtmap
from edtmap import _edtmap


def stub_names():
    tree = ast.parse((Path(__file__).resolve().parents[1] / "edtmap" / "_edtmap.pyi").read_text())
    top, members = set(), {}
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            top.add(node.name)
        if isinstance(node, ast.ClassDef):
            members[node.name] = {n.name for n in node.body if isinstance(n, ast.FunctionDef)}
        if isinstance(node, ast.AnnAssign):
            top.add(node.target.id)
    return top, members


def test_stubs_match_the_module():
    top, members = stub_names()
    public = {n for n in dir(_edtmap) if not n.startswith("_")} | {"__version__"}
    assert top == public
    for cls, names in members.items():
        defined = {n for n in dir(getattr(_edtmap, cls)) if not n.startswith("_")}
        defined |= {n for n in ("__init__", "__len__", "__iter__", "__next__") if n in names}
        assert names == defined, cls


def test_package_exports():
    for name in edtmap.__all__:
        assert hasattr(edtmap, name), name
    assert (Path(edtmap.__file__).parent / "py.typed").exists()
