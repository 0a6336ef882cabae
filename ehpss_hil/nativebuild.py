"""Builds the native extensions of :mod:`.native` with mypyc: ``python -m ehpss_hil.nativebuild``.

``build`` (the default) compiles :func:`.native.modules` in place from the repository root and
writes the manifest; ``clean`` removes what a build made; ``status`` says whether the compiled
modules are the ones imported. ``make`` runs ``build`` when it sets up ``.venv`` (``make
native`` again after editing a compiled module; until then they run from source).
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import sysconfig
from collections.abc import Sequence
from pathlib import Path

from .native import (
    GROUP,
    MANIFEST,
    PACKAGE_DIR,
    SHARED_LIB,
    extension,
    modules,
    on_disk,
    record,
    source,
    status,
)

#: where the build puts mypyc's generated C, the objects and its log (below the repository)
BUILD_DIR = Path("build") / "native"


def clean(root: Path) -> int:
    """Remove the extensions, the manifest and the build directory; the number of files removed."""
    n = _remove_products()
    shutil.rmtree(root / BUILD_DIR, ignore_errors=True)
    return n


def _remove_products() -> int:
    """Remove the extensions, the group's shared library and the manifest; how many files."""
    n = 0
    for ext in on_disk().values():
        ext.unlink()
        n += 1
    for lib in PACKAGE_DIR.glob(SHARED_LIB.rsplit(".", 1)[1] + ".*"):
        lib.unlink()
        n += 1
    if MANIFEST.exists():
        MANIFEST.unlink()
        n += 1
    return n


_SETUP = """
import sys
from mypyc.build import mypycify
from setuptools import setup
setup(
    name="ehpss_hil_native",
    ext_modules=mypycify(sys.argv[1:], opt_level="3", group_name={group!r}, target_dir={target!r}),
    script_args=["-q", "build_ext", "--inplace", "--build-temp", {temp!r}],
)
"""


def build(root: Path) -> int:
    """Compile :func:`modules` in place (run from the repository ``root``) and write the
    manifest. Returns 0: built, or one line on why not (no mypyc, no C compiler or Python
    headers, a failed compile with its log kept) — everything then runs from source, which is
    never wrong, only slower (``status`` says which; CI requires the build)."""
    if importlib.util.find_spec("mypyc") is None or importlib.util.find_spec("setuptools") is None:
        print("native build skipped: mypyc (mypy) and setuptools are not installed; running from source")
        return 0
    if shutil.which(os.environ.get("CC", "cc")) is None:
        print("native build skipped: no C compiler (cc); running from source")
        return 0
    if not (Path(sysconfig.get_paths()["include"]) / "Python.h").exists():
        print("native build skipped: no Python headers (Python.h; python3-dev); running from source")
        return 0
    clean(root)
    out = root / BUILD_DIR
    out.mkdir(parents=True, exist_ok=True)
    log = out / "build.log"
    names = modules()
    paths = [str(source(m).relative_to(root)) for m in names]
    code = _SETUP.format(group=GROUP, target=str(BUILD_DIR / "c"), temp=str(BUILD_DIR / "obj"))
    with log.open("w", encoding="utf-8") as fh:
        proc = subprocess.run(
            [sys.executable, "-c", code, *paths], cwd=root, stdout=fh, stderr=subprocess.STDOUT, check=False
        )
    missing = [m for m in names if extension(m) is None]
    if proc.returncode != 0 or missing:
        clean_n = _remove_products()
        print(
            f"native build failed (exit {proc.returncode}, {len(missing)} extension(s) missing; "
            f"log: {log.relative_to(root)}); {clean_n} file(s) removed, running from source"
        )
        return 0
    manifest = {"python": sys.version, "modules": {m: record(source(m)) for m in names}}
    MANIFEST.write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    print(f"native build: {len(names)} modules compiled with mypyc (log: {log.relative_to(root)})")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m ehpss_hil.nativebuild [build|clean|status]``."""
    args = list(sys.argv[1:] if argv is None else argv)
    root = PACKAGE_DIR.parent
    if args in ([], ["build"]):
        return build(root)
    if args == ["clean"]:
        print(f"native clean: {clean(root)} file(s) removed")
        return 0
    if args == ["status"]:
        print(status())
        return 0
    print("usage: python -m ehpss_hil.nativebuild [build|clean|status]", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
