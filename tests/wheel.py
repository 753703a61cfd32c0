"""A pure-Python project folder as a wheel, installed by pip: a real distribution for tests.

:func:`build_wheel` writes a PEP 427 wheel (``METADATA``, ``WHEEL``, ``entry_points.txt``,
``RECORD`` with SHA-256 hashes) from the project's ``pyproject.toml`` and its one package
folder, with no build backend (a fresh venv need not have setuptools' ``bdist_wheel``, and
the tests run offline). :func:`pip_install` installs it with pip into a folder of its own,
so its entry points are visible to :mod:`importlib.metadata` of any interpreter that has the
folder on ``sys.path`` (``PYTHONPATH``), and the test's virtualenv is left as it was.
"""

from __future__ import annotations

import base64
import hashlib
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path


def _record_hash(data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=")
    return f"sha256={digest.decode()}"


def build_wheel(project: Path, out: Path) -> Path:
    """Build ``project`` (``pyproject.toml`` with ``[project]`` name, version, entry points;
    one package folder named after the distribution) into a wheel in ``out``."""
    meta = tomllib.loads((project / "pyproject.toml").read_text("utf-8"))["project"]
    name, version = meta["name"], meta["version"]
    dist = name.replace("-", "_")
    package = project / dist
    files: dict[str, bytes] = {
        str(p.relative_to(project)).replace("\\", "/"): p.read_bytes()
        for p in sorted(package.rglob("*.py"))}
    info = f"{dist}-{version}.dist-info"
    requires = "".join(f"Requires-Dist: {d}\n" for d in meta.get("dependencies", []))
    files[f"{info}/METADATA"] = (f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n"
                                 f"Summary: {meta.get('description', '')}\n{requires}").encode()
    files[f"{info}/WHEEL"] = (b"Wheel-Version: 1.0\nGenerator: sitframe-tests\n"
                              b"Root-Is-Purelib: true\nTag: py3-none-any\n")
    eps = []
    for group, entries in meta.get("entry-points", {}).items():
        eps.append(f"[{group}]")
        eps += [f"{k} = {v}" for k, v in entries.items()]
    files[f"{info}/entry_points.txt"] = ("\n".join(eps) + "\n").encode()
    record = [f"{path},{_record_hash(data)},{len(data)}" for path, data in files.items()]
    files[f"{info}/RECORD"] = ("\n".join([*record, f"{info}/RECORD,,"]) + "\n").encode()
    out.mkdir(parents=True, exist_ok=True)
    wheel = out / f"{dist}-{version}-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w", zipfile.ZIP_DEFLATED) as zf:
        for path, data in files.items():
            zf.writestr(path, data)
    return wheel


def pip_install(wheel: Path, target: Path) -> subprocess.CompletedProcess[str]:
    """``pip install --no-deps --no-index --target TARGET WHEEL`` with this interpreter."""
    return subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-index",
                           "--disable-pip-version-check", "--target", str(target), str(wheel)],
                          capture_output=True, text=True, timeout=300)
