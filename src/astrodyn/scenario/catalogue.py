"""The catalogue of scenario configs shipped in the repository's ``configs/`` folder."""

from __future__ import annotations

from pathlib import Path

__all__ = ["configs_dir", "config_path"]


def configs_dir() -> Path:
    """The repository's ``configs/`` folder (it sits beside ``src/``).

    Found from the package's own path, so it is there for an editable install
    (``make install``) or a run from the source tree; an installed wheel has no
    catalogue, and :class:`FileNotFoundError` says so: pass a config path instead.
    """
    here = Path(__file__).resolve()
    for parent in here.parents:
        cand = parent / "configs"
        if (cand / "demo.toml").is_file():
            return cand
    raise FileNotFoundError("configs/: the catalogue of scenario configs is not beside the astrodyn sources "
                            "(an installed wheel has none); pass the path of a config file")


def config_path(name: str) -> Path:
    """``configs/<name>.toml`` of the catalogue (``name`` without ``.toml``)."""
    path = configs_dir() / f"{name}.toml"
    if not path.is_file():
        raise FileNotFoundError(f"configs/{name}.toml: no such scenario in the catalogue")
    return path
