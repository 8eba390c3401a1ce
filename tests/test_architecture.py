"""The layering of docs/architecture.md (section 1, "Layers") as checks that run with
every ``pytest``: the import-linter contracts of ``pyproject.toml``, ruff, and no
underscored name imported from another astrodyn module."""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"


def _tool(name: str) -> str:
    """The console script ``name`` of this interpreter's environment (the venv), else PATH."""
    local = Path(sys.executable).parent / name
    if local.exists():
        return str(local)
    found = shutil.which(name)
    if found is None:
        pytest.fail(f"{name} is not installed: it is in the 'test' extra (pip install -e '.[test]')")
    return found


def _run(args: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=300)


def test_import_contracts_hold():
    """lint-imports: every [tool.importlinter] contract of pyproject.toml is kept."""
    p = _run([_tool("lint-imports"), "--no-cache"])
    assert p.returncode == 0, p.stdout[-4000:] + p.stderr[-2000:]
    assert "broken" in p.stdout and " 0 broken" in p.stdout, p.stdout[-2000:]


def test_ruff_is_clean():
    """ruff check src tests with the [tool.ruff] configuration of pyproject.toml."""
    p = _run([_tool("ruff"), "check", "--no-cache", "src", "tests"])
    assert p.returncode == 0, p.stdout[-4000:] + p.stderr[-2000:]


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def private_imports(path: Path, module: str | None = None) -> list[str]:
    """Places in ``path`` (the module ``module``, by default named from its place under
    src/) that take an underscored name from another astrodyn module:
    ``from astrodyn.x import _name``, ``import astrodyn._x``, or ``x._name`` where ``x``
    was bound to an astrodyn module by an import."""
    module = module or _module_name(path)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    found, module_aliases = [], {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([node.module] if node.module else []))
            if base != "astrodyn" and not base.startswith("astrodyn."):
                continue
            if base != module and any(_private(p) for p in base.split(".")):
                found.append(f"{path}:{node.lineno}: from {base} import ...")
            for alias in node.names:
                if _private(alias.name) and base != module:
                    found.append(f"{path}:{node.lineno}: from {base} import {alias.name}")
                module_aliases[alias.asname or alias.name] = f"{base}.{alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("astrodyn"):
                    if any(_private(p) for p in alias.name.split(".")):
                        found.append(f"{path}:{node.lineno}: import {alias.name}")
                    if alias.asname:
                        module_aliases[alias.asname] = alias.name
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr) and isinstance(node.value, ast.Name):
            target = module_aliases.get(node.value.id)
            if target is not None and target != module:
                found.append(f"{path}:{node.lineno}: {node.value.id}.{node.attr} ({target})")
    return found


def test_no_private_names_across_modules():
    """docs/architecture.md section 1: what is shared gets a public name in the module
    named for it; no module of the package (nor a services/ script) reaches into
    another's underscored names."""
    found = [hit for path in sorted(SRC.rglob("*.py")) for hit in private_imports(path)]
    found += [hit for path in sorted((ROOT / "services").glob("*.py"))
              for hit in private_imports(path, f"services.{path.stem}")]
    assert not found, "underscored names imported across modules:\n" + "\n".join(found)


def test_private_import_check_catches_each_form(tmp_path):
    """The checker itself: each form of reaching into another module is reported, and a
    module's own names and public names are not."""
    probe = tmp_path / "probe.py"
    probe.write_text(
        "from astrodyn.orbit.kepler import _run, solve_kepler\n"
        "from . import kepler\n"
        "from astrodyn.orbit import universal as uni\n"
        "import astrodyn.orbit._hidden\n"
        "x = kepler._broadcast_flat\n"
        "y = uni._stumpff\n"
        "z = uni.propagate\n",
        encoding="utf-8",
    )
    hits = private_imports(probe, "astrodyn.orbit.probe")
    text = "\n".join(hits)
    assert "import _run" in text and "solve_kepler" not in text
    assert "kepler._broadcast_flat" in text and "uni._stumpff" in text
    assert "astrodyn.orbit._hidden" in text and "propagate" not in text
    assert len(hits) == 4, text


def test_orbit_package_reexports_its_modules():
    """astrodyn.orbit lists its names explicitly (no star imports): the list is the union of
    the public lists of the modules it gathers, so a name added there is not forgotten."""
    import astrodyn.orbit as orbit
    from astrodyn.orbit import elements, kepler, perturbations, universal

    expected = set(elements.__all__) | set(perturbations.__all__) | set(kepler.__all__) | set(universal.__all__)
    assert set(orbit.__all__) == expected
    assert all(getattr(orbit, name) is not None for name in orbit.__all__)


def test_code_cites_docs_in_the_repository():
    """Code cites docs/architecture.md (or another page of docs/), never notes outside the
    repository, and every docs/ page it names exists."""
    import re

    outside, missing = [], []
    for path in sorted(SRC.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        if "design.md" in text:
            outside.append(str(path.relative_to(ROOT)))
        for page in set(re.findall(r"docs/[\w.-]+\.md", text)):
            if not (ROOT / page).exists():
                missing.append(f"{path.relative_to(ROOT)}: {page}")
    assert not outside, f"cite docs/architecture.md instead of design.md in: {outside}"
    assert not missing, f"cited pages that do not exist: {missing}"


def test_renamed_public_names_keep_working():
    """Homonyms got distinct names in issue 12; the old public names stay as aliases."""
    import astrodyn.attitude as attitude
    import astrodyn.recording as recording
    import astrodyn.simulate as simulate
    from astrodyn.orbit.perturbations import CentralBody as GravityCentralBody
    from astrodyn.scenario import CentralBody
    from astrodyn.scenario.ephemeris import third_body_state

    assert recording.Body is recording.BodyTracks
    assert attitude.euler_rates is attitude.angular_acceleration
    assert simulate.third_body_state is third_body_state
    cb = CentralBody(name="earth", mu=3.986e14, radius=6.378e6, J=(1.08e-3, -2.5e-6, 0.0, 0.0, 0.0), frame="GCRF")
    assert isinstance(cb, GravityCentralBody) and cb.j == cb.J
    assert list(cb.to_dict()) == ["name", "mu", "radius", "j", "frame"]  # the recorded metadata's keys


def test_every_top_level_module_has_a_layer():
    """A new module or subpackage of astrodyn is placed in a layer: it appears in the layers
    contract of pyproject.toml (else import-linter would not check it at all)."""
    import re
    import tomllib

    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    layers = next(c for c in config["tool"]["importlinter"]["contracts"] if c["type"] == "layers")["layers"]
    listed = {name for layer in layers for name in re.split(r"[|:]", layer) if name.strip()}
    listed = {name.strip() for name in listed}
    package = SRC / "astrodyn"
    present = {f"astrodyn.{p.stem}" for p in package.glob("*.py") if p.stem not in ("__init__", "__main__")}
    present |= {f"astrodyn.{p.name}" for p in package.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    missing = sorted(present - listed)
    assert not missing, (f"{missing}: add each to a layer of the layers contract in pyproject.toml "
                         "([tool.importlinter]) and to the table of docs/architecture.md, section 1")
