"""The code behind a plugin method's numbers (dbench/run/identity.py method_files): its package
folder (every file of it, its weights included) even when that folder is called ``methods``,
the modules of its package it imports, the modules a stand-alone plugin file imports from
beside it, and the classes it inherits from (a built-in method's files), so an
edit to any of them changes its cells' identity."""
import importlib.util
import sys
from pathlib import Path

from dbench.run import identity


def _load(monkeypatch, path: Path, name: str):
    """Import ``name`` (a package module under ``path``'s root, or the file ``path`` itself)
    as a plugin would be; the modules stay in sys.modules for the test only (inspect.getfile
    reads them there)."""
    root = path.parents[2] if "." in name else path.parent
    monkeypatch.syspath_prepend(str(root))
    before = set(sys.modules)
    if "." in name:
        module = importlib.import_module(name)
    else:
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    for key in set(sys.modules) - before:  # removed again when the test ends
        monkeypatch.setitem(sys.modules, key, sys.modules[key])
    return module


METHOD = '''from dbench.denoiser import Denoiser
{imports}


class Den(Denoiser):
    def denoise(self, data):
        return data.color * {scale}
'''


def test_a_plugin_package_folder_called_methods_counts_whole(tmp_path, monkeypatch):
    pkg = tmp_path / "mylab" / "methods"
    pkg.mkdir(parents=True)
    (tmp_path / "mylab" / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "util.py").write_text("SCALE = 0.5\n")
    (pkg / "den.py").write_text(METHOD.format(imports="from .util import SCALE",
                                              scale="SCALE"))
    module = _load(monkeypatch, pkg / "den.py", "mylab.methods.den")
    files = {p.name for p in identity.method_files(module.Den)}
    assert {"den.py", "util.py", "__init__.py"} <= files


def test_a_stand_alone_plugin_file_counts_the_helpers_it_imports(tmp_path, monkeypatch):
    (tmp_path / "tmp_helper.py").write_text("SCALE = 0.5\n")
    (tmp_path / "unused.py").write_text("X = 1\n")
    (tmp_path / "mymeth.py").write_text(METHOD.format(imports="import tmp_helper",
                                                      scale="tmp_helper.SCALE"))
    module = _load(monkeypatch, tmp_path / "mymeth.py", "mymeth_plugin")
    files = [p.name for p in identity.method_files(module.Den)]
    assert files == ["mymeth.py", "tmp_helper.py"]
    before = identity.method_version(module.Den)
    (tmp_path / "tmp_helper.py").write_text("SCALE = 0.9\n")
    identity.method_version.cache_clear()  # (one version per process: code is read once)
    assert identity.method_version(module.Den) != before


def test_a_plugin_subclass_counts_the_built_in_method_it_inherits(tmp_path, monkeypatch):
    (tmp_path / "sub.py").write_text("from dbench.methods.noisy import Noisy\n\n\n"
                                     "class MyNoisy(Noisy):\n    pass\n")
    module = _load(monkeypatch, tmp_path / "sub.py", "sub_plugin")
    files = identity.method_files(module.MyNoisy)
    noisy = Path(sys.modules["dbench.methods.noisy"].__file__).resolve()
    assert noisy in files and (tmp_path / "sub.py").resolve() in files


def test_a_plugin_package_counts_its_weights_and_the_modules_of_its_package_it_imports(
        tmp_path, monkeypatch):
    # a package's weights in a format of its own and a module of the package outside the
    # method's folder decide its numbers: a change to either changed nothing in the identity,
    # so a sweep reused the cells computed with the old ones
    pkg = tmp_path / "mylab2" / "methods"
    pkg.mkdir(parents=True)
    (tmp_path / "mylab2" / "__init__.py").write_text("")
    (tmp_path / "mylab2" / "common.py").write_text("SCALE = 0.5\n")
    (pkg / "__init__.py").write_text("")
    (pkg / "weights.npy").write_bytes(b"\x93NUMPY one")
    (pkg / "__pycache__").mkdir()
    (pkg / "__pycache__" / "den.cpython-312.pyc").write_bytes(b"compiled")
    (pkg / ".DS_Store").write_bytes(b"finder")
    (pkg / "den.py").write_text(METHOD.format(imports="from ..common import SCALE",
                                              scale="SCALE"))
    module = _load(monkeypatch, pkg / "den.py", "mylab2.methods.den")
    files = {p.name for p in identity.method_files(module.Den)}
    assert files == {"__init__.py", "den.py", "weights.npy", "common.py"}
    versions = {identity.method_version(module.Den)}
    for path, text in ((pkg / "weights.npy", b"\x93NUMPY two"),
                       (tmp_path / "mylab2" / "common.py", b"SCALE = 0.9\n")):
        path.write_bytes(text)
        identity.method_version.cache_clear()
        versions.add(identity.method_version(module.Den))
    assert len(versions) == 3


def test_a_stand_alone_plugin_file_counts_a_package_beside_it_that_it_imports(tmp_path,
                                                                            monkeypatch):
    # 'from sibhelpers import SCALE' with sibhelpers/ a folder: only a sibhelpers.py was looked
    # for, so an edit to the package left the plugin's cells in place
    (tmp_path / "sibhelpers").mkdir()
    (tmp_path / "sibhelpers" / "__init__.py").write_text("SCALE = 0.5\n")
    (tmp_path / "sibmeth.py").write_text(METHOD.format(imports="from sibhelpers import SCALE",
                                                       scale="SCALE"))
    module = _load(monkeypatch, tmp_path / "sibmeth.py", "sibmeth_plugin")
    assert [p.name for p in identity.method_files(module.Den)] == ["__init__.py", "sibmeth.py"]
    before = identity.method_version(module.Den)
    (tmp_path / "sibhelpers" / "__init__.py").write_text("SCALE = 0.9\n")
    identity.method_version.cache_clear()
    assert identity.method_version(module.Den) != before


def test_a_plugin_file_in_latin_1_or_with_a_byte_order_mark_is_versioned(tmp_path, monkeypatch):
    # Python imports both, but the identity read them as UTF-8 text: dbench sweep ended in an
    # internal error (UnicodeDecodeError; SyntaxError on U+FEFF)
    (tmp_path / "latinmeth.py").write_bytes(
        b"# -*- coding: latin-1 -*-\n# caf\xe9\n" + METHOD.format(imports="", scale=2).encode())
    (tmp_path / "bommeth.py").write_bytes(
        b"\xef\xbb\xbf" + METHOD.format(imports="", scale=2).encode())
    for stem in ("latinmeth", "bommeth"):
        module = _load(monkeypatch, tmp_path / f"{stem}.py", f"{stem}_plugin")
        assert identity.method_version(module.Den)
    # a package's file that is no Python (a template, never imported) counts by its bytes
    pkg = tmp_path / "tplpkg" / "methods"
    pkg.mkdir(parents=True)
    (tmp_path / "tplpkg" / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "template.py").write_text("{{ not python }}\n")
    (pkg / "den.py").write_text(METHOD.format(imports="", scale=2))
    module = _load(monkeypatch, pkg / "den.py", "tplpkg.methods.den")
    assert "template.py" in {p.name for p in identity.method_files(module.Den)}
    assert identity.method_version(module.Den)


def test_a_namespace_package_module_counts_the_modules_it_imports_relatively(tmp_path,
                                                                           monkeypatch):
    # nsplug/sub/ has no __init__.py (PEP 420): 'from .nshelper import SCALE' was not followed,
    # so an edit to nshelper.py left the method's cells in place
    sub = tmp_path / "nsplug" / "sub"
    sub.mkdir(parents=True)
    (sub / "nshelper.py").write_text("SCALE = 0.5\n")
    (sub / "nsmeth.py").write_text(METHOD.format(imports="from .nshelper import SCALE",
                                                 scale="SCALE"))
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("nsplug.sub.nsmeth")
    for key in [k for k in sys.modules if k.startswith("nsplug")]:
        monkeypatch.setitem(sys.modules, key, sys.modules[key])
    assert [p.name for p in identity.method_files(module.Den)] == ["nshelper.py", "nsmeth.py"]
