"""astrodyn.scenario: every shipped config loads; every error path names the field;
units, epochs and elements are checked against independent computations; random and
mutated TOML never escapes as anything but a ScenarioError.

Independent references: Curtis, Orbital Mechanics for Engineering Students (3rd ed.),
Example 4.7 (elements -> state, published to 4 digits); a hand-written perifocal ->
inertial 3-1-3 rotation; Kepler's and Barker's equations evaluated on the loaded state;
the IERS offsets TAI - UTC = 37 s (since 2017), TT - TAI = 32.184 s, |TDB - TT| < 1.7 ms;
the Walker pattern definition.
"""

from __future__ import annotations

import datetime as dt
import json
import math
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from astrodyn import scenario as S
from astrodyn.scenario import ScenarioError, fields as F

CONFIGS = sorted((Path(__file__).resolve().parent.parent / "configs").glob("*.toml"))
REQUIRED = {"demo", "leo-gravity-gradient", "molniya-j2", "hyperbolic-flyby", "near-parabolic-comet",
            "dzhanibekov", "spinning-top", "dual-spin", "constellation-1000"}
MU_E, R_E = S.CENTRAL_BODIES["earth"][:2]


# --------------------------------------------------------------------------- a tiny TOML writer


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def to_toml(data: dict, prefix: str = "") -> str:
    """TOML text for nested dicts (tables) and lists of dicts (arrays of tables)."""
    scalars, tables, arrays = [], [], []
    for k, v in data.items():
        key = json.dumps(k)
        if isinstance(v, dict):
            tables.append((key, v))
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            arrays.append((key, v))
        else:
            scalars.append(f"{key} = {_toml_value(v)}")
    out = "\n".join(scalars) + "\n"
    for key, v in tables:
        name = f"{prefix}.{key}" if prefix else key
        out += f"\n[{name}]\n" + to_toml(v, name)
    for key, items in arrays:
        name = f"{prefix}.{key}" if prefix else key
        for item in items:
            out += f"\n[[{name}]]\n" + to_toml(item, name)
    return out


def base() -> dict:
    """A small valid config as a dict (fresh copy each call)."""
    return {
        "scenario": {"name": "t", "epoch": "2026-03-20T12:00:00 UTC", "duration": "10 s", "rate": "1 Hz"},
        "central_body": {"name": "earth"},
        "bodies": [
            {"name": "a", "orbit": {"a": "7000 km", "e": 0.1, "i": "30 deg", "raan": "10 deg", "argp": "20 deg", "nu": "40 deg"},
             "attitude": {"q": [1, 0, 0, 0], "w": ["0.1 rad/s", "0 rad/s", "0 rad/s"], "inertia": ["1 kg m2", "2 kg m2", "2.5 kg m2"]}},
            {"name": "b", "orbit": {"r": ["7000 km", "0 km", "0 km"], "v": ["0 km/s", "7.5 km/s", "0 km/s"]}},
            {"name": "c", "attitude": {"euler": ["10 deg", "20 deg", "30 deg"], "seq": "321", "inertia": ["1 kg m2", "1 kg m2", "1 kg m2"], "model": "torque_free"}},
        ],
    }


def load(d: dict) -> S.Scenario:
    return S.load_dict(d, source="configs/x.toml")


# --------------------------------------------------------------------------- shipped configs


def test_required_configs_exist():
    assert REQUIRED <= {p.stem for p in CONFIGS}


@pytest.mark.parametrize("path", CONFIGS, ids=[p.stem for p in CONFIGS])
def test_every_config_loads_and_plans(path):
    text = path.read_text()
    assert text.lstrip().startswith("#"), "each config starts with comments explaining the physics"
    scn = S.load(path)
    assert scn.name == path.stem
    assert scn.bodies and scn.duration > 0 and scn.rate > 0
    for b in scn.bodies:
        if b.orbit is not None:
            assert b.orbit.r0.shape == (3,) and np.all(np.isfinite(b.orbit.r0)) and np.all(np.isfinite(b.orbit.v0))
        if b.attitude is not None:
            assert abs(np.linalg.norm(b.attitude.q0) - 1) < 1e-15 * 4
    p = S.plan(scn)
    assert p.processes[-1] == "logger" and len(p.bodies) == len(scn.bodies)
    d = scn.to_dict()
    text = json.dumps(d, allow_nan=False)  # JSON-safe, no NaN
    meta = scn.to_metadata()
    assert all(isinstance(v, str) for v in meta.values()) and json.loads(meta["json"])["name"] == scn.name
    again = S.load_dict(json.loads(text)["config"], source=str(path))  # the config as run reloads
    for b1, b2 in zip(scn.bodies, again.bodies):
        if b1.orbit is not None:
            assert np.array_equal(b1.orbit.r0, b2.orbit.r0) and np.array_equal(b1.orbit.v0, b2.orbit.v0)


def test_demo_is_short_and_has_orbit_and_attitude():
    scn = S.load(next(p for p in CONFIGS if p.stem == "demo"))
    p = S.plan(scn)
    assert {"orbit", "attitude", "logger"} == set(p.processes)
    assert 2 <= len(scn.bodies) <= 10 and p.messages < 100_000  # finishes in < 1 min headless


def test_constellation_is_a_walker_delta():
    scn = S.load(next(p for p in CONFIGS if p.stem == "constellation-1000"))
    assert len(scn.bodies) == 1000 and len({b.name for b in scn.bodies}) == 1000
    assert scn.rate == 10.0 and all(b.attitude is not None for b in scn.bodies)
    names, r, v = scn.orbit_arrays()
    a = R_E + 550e3
    rn = np.linalg.norm(r, axis=1)
    # circular: |r| = a and |v| = sqrt(mu/a); conditioning ~ a few ulp of a sin/cos chain
    np.testing.assert_allclose(rn, a, rtol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), math.sqrt(MU_E / a), rtol=1e-14)
    h = np.cross(r, v)
    incl = np.degrees(np.arccos(h[:, 2] / np.linalg.norm(h, axis=1)))
    np.testing.assert_allclose(incl, 53.0, atol=1e-9)
    node = np.degrees(np.arctan2(h[:, 0], -h[:, 1])) % 360  # raan from h = |h| (sin i sin O, -sin i cos O, cos i)
    plane = np.arange(1000) // 50
    np.testing.assert_allclose(((node - 18.0 * plane + 180) % 360) - 180, 0, atol=1e-9)
    # argument of latitude u: angle from the node line to r, in the orbit plane
    n_hat = np.stack([np.cos(np.radians(node)), np.sin(np.radians(node)), np.zeros(1000)], axis=1)
    u = np.degrees(np.arctan2(np.einsum("ij,ij->i", np.cross(n_hat, r), h / np.linalg.norm(h, axis=1)[:, None]), np.einsum("ij,ij->i", n_hat, r))) % 360
    k = np.arange(1000) % 50
    expected = (7.2 * k + 0.36 * plane) % 360  # 360/s per slot, f*360/t per plane (f = 1)
    np.testing.assert_allclose(((u - expected + 180) % 360) - 180, 0, atol=1e-9)
    assert scn.bodies[0].name == "sat-00-00" and scn.bodies[-1].name == "sat-19-49"


# --------------------------------------------------------------------------- units and epochs


@pytest.mark.parametrize(
    "text,kind,si",
    [
        ("7000 km", "length", 7.0e6),
        ("0.3 AU", "length", 0.3 * 1.495978707e11),
        ("3 cm", "length", 0.03),
        ("51.6 deg", "angle", math.radians(51.6)),
        ("0.1 rad/s", "angular_velocity", 0.1),
        ("60 rpm", "angular_velocity", 2 * math.pi),
        ("10 deg/s", "angular_velocity", math.radians(10)),
        ("10 Hz", "frequency", 10.0),
        ("1/min", "frequency", 1 / 60),
        ("90 min", "time", 5400.0),
        ("2 d", "time", 172800.0),
        ("7.5 km/s", "speed", 7500.0),
        ("398600 km3/s2", "gm", 3.986e14),
        ("100 kg m2", "inertia", 100.0),
        ("10 N m s", "angular_momentum", 10.0),
        ("9.81 m/s2", "acceleration", 9.81),
        ("256 MB", "bytes", 256e6),
        # units with digits in them, not scale factors (a number after the value is refused: F4)
        ("10 1/s", "frequency", 10.0),
        ("10 1 / s", "frequency", 10.0),
        ("2 rad s-1", "angular_velocity", 2.0),
        ("1e3 km", "length", 1.0e6),
        ("3.986004418e5 km3 / s2", "gm", 3.986004418e14),
        (7000, "length", 7000.0),  # bare numbers are SI
        (0.5, "angle", 0.5),
    ],
)
def test_quantity_parsing(text, kind, si):
    got = F.quantity(F.Ctx("f"), text, kind, "k")
    assert got == pytest.approx(si, rel=1e-15)  # unit factors are exact decimals or one product


def test_vector_forms():
    ctx = F.Ctx("f")
    np.testing.assert_array_equal(F.vector(ctx, "[7000, 0, -1] km", "length", 3, "r"), [7e6, 0, -1e3])
    np.testing.assert_array_equal(F.vector(ctx, ["7000 km", 0, "1 m"], "length", 3, "r"), [7e6, 0, 1])


def _unix(y, mo, d, h=0, mi=0, s=0):
    return int(dt.datetime(y, mo, d, h, mi, s, tzinfo=dt.UTC).timestamp()) * 10**9


def test_epochs_in_every_scale():
    d = base()
    scn = load(d)
    assert scn.epoch_unix_ns == _unix(2026, 3, 20, 12) and scn.epoch_scale == "utc"
    d["scenario"]["epoch"] = "2026-03-20T12:00:00 TAI"  # TAI - UTC = 37 s since 2017-01-01
    assert load(d).epoch_unix_ns == _unix(2026, 3, 20, 12) - 37 * 10**9
    d["scenario"]["epoch"] = "2026-03-20T12:00:00 TT"  # TT = TAI + 32.184 s
    assert load(d).epoch_unix_ns == _unix(2026, 3, 20, 12) - 69_184_000_000
    d["scenario"]["epoch"] = "2026-03-20T12:00:00 TDB"  # |TDB - TT| < 1.7 ms (Fairhead & Bretagnon)
    scn = load(d)
    assert abs(scn.epoch_unix_ns - (_unix(2026, 3, 20, 12) - 69_184_000_000)) < 1_700_000
    assert scn.epoch == "2026-03-20T12:00:00 TDB" and scn.epoch_scale == "tdb"
    d["scenario"]["epoch"] = "2026-03-20T12:00:00.123456789"  # default UTC, ns kept
    assert load(d).epoch_unix_ns == _unix(2026, 3, 20, 12) + 123_456_789
    d["scenario"]["epoch"] = dt.datetime(2026, 3, 20, 14, 0, tzinfo=dt.timezone(dt.timedelta(hours=2)))  # TOML date-time
    assert load(d).epoch_unix_ns == _unix(2026, 3, 20, 12)


def test_epoch_on_a_leap_second_day_is_posix_time():
    # 2016-12-31 had 86401 s; POSIX time ignores the leap second (23:59:60 -> next 00:00:00)
    d = base()
    d["scenario"]["epoch"] = "2016-12-31T12:00:00 UTC"
    assert load(d).epoch_unix_ns == _unix(2016, 12, 31, 12)
    d["scenario"]["epoch"] = "2016-12-31T23:59:60 UTC"
    assert load(d).epoch_unix_ns == _unix(2017, 1, 1)
    d["scenario"]["epoch"] = "2017-01-01T00:00:00 TAI"  # TAI - UTC was 36 s before, 37 s after
    assert load(d).epoch_unix_ns == _unix(2016, 12, 31, 23, 59, 24)


def test_no_network_for_astropy():
    from astropy.utils import iers

    load(base())
    assert iers.conf.auto_download is False


# --------------------------------------------------------------------------- elements -> state


def _perifocal_to_inertial(p, e, i, raan, argp, nu, mu):
    """Hand computation: perifocal r, v rotated by R3(-raan) R1(-i) R3(-argp) (Curtis eq. 4.44-4.49)."""
    r_pf = p / (1 + e * math.cos(nu)) * np.array([math.cos(nu), math.sin(nu), 0.0])
    v_pf = math.sqrt(mu / p) * np.array([-math.sin(nu), e + math.cos(nu), 0.0])

    def R3(a):
        return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])

    def R1(a):
        return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])

    Q = R3(raan) @ R1(i) @ R3(argp)
    return Q @ r_pf, Q @ v_pf


def test_elements_curtis_example_4_7():
    # Curtis 3rd ed. Example 4.7: h = 80 000 km^2/s, e = 1.4, i = 30, raan = 40, argp = 60,
    # nu = 30 deg, mu = 398 600 km^3/s^2 -> r = (-4040, 4815, 3629) km,
    # v = (-10.39, -4.772, 1.744) km/s (printed to 4 significant digits).
    d = base()
    p_km = 80000.0**2 / 398600.0
    d["central_body"] = {"name": "earth", "mu": "398600 km3/s2"}
    d["bodies"] = [{"name": "x", "orbit": {"p": f"{p_km!r} km", "e": 1.4, "i": "30 deg", "raan": "40 deg", "argp": "60 deg", "nu": "30 deg"}}]
    o = load(d).bodies[0].orbit
    # 4 printed digits: half a unit in the 4th digit is <= 1.3e-3 relative for these values
    np.testing.assert_allclose(o.r0 / 1e3, [-4040, 4815, 3629], rtol=1.5e-3)
    np.testing.assert_allclose(o.v0 / 1e3, [-10.39, -4.772, 1.744], rtol=1.5e-3)


@pytest.mark.parametrize(
    "size,e,i,raan,argp,nu",
    [
        ({"a": "7000 km"}, 0.1, 30, 10, 20, 40),
        ({"a": "26600 km"}, 0.74, 63.4, 0, 270, 180),
        ({"a": "-4000 km"}, 100.0, 120, 300, 10, -89),
        ({"rp": "7000 km"}, 1.0, 45, 45, 45, 100),
        ({"p": "9000 km"}, 0.0, 0, 0, 0, 123),
        ({"rp": "0.3 AU"}, 0.999999, 144, 60, 110, -170),
    ],
)
def test_elements_to_state_against_hand_computation(size, e, i, raan, argp, nu):
    d = base()
    d["bodies"] = [{"name": "x", "orbit": dict(size, e=e, i=f"{i} deg", raan=f"{raan} deg", argp=f"{argp} deg", nu=f"{nu} deg")}]
    o = load(d).bodies[0].orbit
    key, value = next(iter(size.items()))
    x = F.quantity(F.Ctx("f"), value, "length", key)
    p = {"a": x * (1 - e * e), "p": x, "rp": x * (1 + e)}[key]
    r, v = _perifocal_to_inertial(p, e, *map(math.radians, (i, raan, argp, nu)), MU_E)
    # a handful of roundings in each product chain: 1e-12 relative to the vector norm is ~100x that
    assert np.linalg.norm(o.r0 - r) <= 1e-12 * np.linalg.norm(r)
    assert np.linalg.norm(o.v0 - v) <= 1e-12 * np.linalg.norm(v)


def _true_anomaly(r, v, mu):
    h = np.cross(r, v)
    e_vec = np.cross(v, h) / mu - r / np.linalg.norm(r)
    e = np.linalg.norm(e_vec)
    nu = math.atan2(np.dot(np.cross(e_vec, r), h) / np.linalg.norm(h), np.dot(e_vec, r))
    return nu, e


@pytest.mark.parametrize("e,M", [(0.1, 0.5), (0.74, 3.0), (0.9, -2.0), (0.5, 0.0)])
def test_mean_anomaly_satisfies_kepler_equation(e, M):
    d = base()
    d["bodies"] = [{"name": "x", "orbit": {"a": "10000 km", "e": e, "i": "20 deg", "raan": "30 deg", "argp": "40 deg", "M": M}}]
    o = load(d).bodies[0].orbit
    nu, e_got = _true_anomaly(o.r0, o.v0, MU_E)
    E = 2 * math.atan(math.sqrt((1 - e_got) / (1 + e_got)) * math.tan(nu / 2))
    # e recovered from the state carries ~1e-15 error; Kepler's residual then ~1e-14
    assert abs(math.remainder(E - e_got * math.sin(E) - M, 2 * math.pi)) < 1e-12


def test_parabolic_mean_anomaly_satisfies_barker():
    d = base()
    d["bodies"] = [{"name": "x", "orbit": {"rp": "8000 km", "e": 1.0, "i": "20 deg", "M": -0.5}}]
    o = load(d).bodies[0].orbit
    nu = o.elements["nu"]
    D = math.tan(nu / 2)
    assert abs(D + D**3 / 3 - (-0.5)) < 1e-14  # Barker's equation, M = D + D^3/3
    r, v = _perifocal_to_inertial(16000e3, 1.0, math.radians(20), 0, 0, nu, MU_E)
    assert np.linalg.norm(o.r0 - r) <= 1e-12 * np.linalg.norm(r)


def test_euler_angles_give_the_dcm_of_the_sequence():
    # seq "321": C = C1(a3) C2(a2) C3(a1) (docs/architecture.md, section 2); check v_body = C v_inertial
    d = base()
    att = load(d).bodies[2].attitude
    a1, a2, a3 = map(math.radians, (10, 20, 30))

    def C1(a):
        return np.array([[1, 0, 0], [0, math.cos(a), math.sin(a)], [0, -math.sin(a), math.cos(a)]])

    def C2(a):
        return np.array([[math.cos(a), 0, -math.sin(a)], [0, 1, 0], [math.sin(a), 0, math.cos(a)]])

    def C3(a):
        return np.array([[math.cos(a), math.sin(a), 0], [-math.sin(a), math.cos(a), 0], [0, 0, 1]])

    C = C1(a3) @ C2(a2) @ C3(a1)
    e0, e = att.q0[0], att.q0[1:]
    Cq = (e0 * e0 - e @ e) * np.eye(3) + 2 * np.outer(e, e) - 2 * e0 * np.array([[0, -e[2], e[1]], [e[2], 0, -e[0]], [-e[1], e[0], 0]])
    np.testing.assert_allclose(Cq, C, atol=1e-15 * 8)  # unit-size entries, a few roundings


def test_full_inertia_tensor_principal_axes():
    d = base()
    c, s = math.cos(0.3), math.sin(0.3)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    tensor = R @ np.diag([1.0, 2.0, 2.5]) @ R.T
    d["bodies"][0]["attitude"]["inertia"] = tensor.tolist()
    a = load(d).bodies[0].attitude
    np.testing.assert_allclose(np.sort(a.principal_moments), [1.0, 2.0, 2.5], rtol=1e-14)
    np.testing.assert_allclose(a.principal_axes @ np.diag(a.principal_moments) @ a.principal_axes.T, tensor, atol=1e-14 * 2.5)
    assert np.linalg.det(a.principal_axes) == pytest.approx(1.0, abs=1e-14)


def test_rotor_h_from_speed_and_inertia():
    d = base()
    d["bodies"][0]["attitude"]["rotors"] = [{"axis": [0, 0, 2], "speed": "60 rpm", "inertia": "0.5 kg m2"}]
    a = load(d).bodies[0].attitude
    assert a.model == "gyrostat" and a.rotors[0].h == pytest.approx(math.pi, rel=1e-15)
    np.testing.assert_array_equal(a.rotors[0].axis, [0, 0, 1])


# --------------------------------------------------------------------------- plan


def test_plan_cheapest_exact_models():
    d = base()
    d["central_body"] = {"name": "earth", "j2": 0.0, "j3": 0.0}
    d["bodies"][0]["orbit"]["model"] = "j2"
    d["bodies"][1]["orbit"]["model"] = "zonal"  # J4..J6 of the Earth are still non-zero
    p = S.plan(load(d))
    assert p.bodies[0].orbit_model == "kepler" and "J2..J2" in p.bodies[0].notes[0]
    assert p.bodies[1].orbit_model == "zonal"
    assert p.bodies[0].attitude_model == "torque_free" and p.bodies[1].attitude_model is None
    assert p.processes == ("orbit", "attitude", "logger")
    assert p.n_steps == 11 and p.messages == 11 * 4
    text = p.text()
    assert "kepler" in text and "exact" in text and "processes: orbit, attitude, logger" in text


def test_plan_attitude_only_and_downgrades():
    d = base()
    d["bodies"] = [
        {"name": "top", "attitude": {"model": "heavy_top", "inertia": [2e-4, 2e-4, 1e-4], "mass": 0.1, "cm": 0.0, "w": [0, 0, 100]}},
        {"name": "ut", "attitude": {"model": "user", "inertia": [1, 2, 2.5], "torque": [0, 0, 0]}},
        {"name": "none", "attitude": {"model": "none"}},
    ]
    p = S.plan(load(d))
    assert p.processes == ("attitude", "logger")
    assert [bp.attitude_model for bp in p.bodies] == ["torque_free", "torque_free", None]
    d["bodies"][0]["attitude"]["cm"] = "3 cm"
    assert S.plan(load(d)).bodies[0].attitude_model == "heavy_top"


def test_periapsis_below_surface_noted():
    d = base()
    d["bodies"] = [{"name": "x", "orbit": {"rp": "6000 km", "e": 1.5}}]
    assert "below the surface" in S.plan(load(d)).bodies[0].notes[0]


def test_output_path_relative_to_config(tmp_path):
    d = base()
    d["output"] = {"path": "out/run.mcap", "roll_size": "64 MiB", "roll_interval": "1 h"}
    cfg = tmp_path / "sub" / "c.toml"
    cfg.parent.mkdir()
    cfg.write_text(to_toml(d))
    scn = S.load(cfg)
    assert scn.output_path == cfg.parent.resolve() / "out" / "run.mcap"
    assert scn.roll_size == 64 * 2**20 and scn.roll_interval == 3600.0


# --------------------------------------------------------------------------- error paths


def _set(d, path, value):
    """Set (or with value=DELETE remove) a dotted path like 'bodies.0.orbit.e'."""
    parts = path.split(".")
    node = d
    for p in parts[:-1]:
        node = node[int(p)] if isinstance(node, list) else node.setdefault(p, {})
    last = parts[-1]
    if value is DELETE:
        if isinstance(node, list):
            node.pop(int(last))
        else:
            node.pop(last)
    elif isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value
    return d


DELETE = object()
NAN = float("nan")

# (dotted path to set, value, expected message after "configs/x.toml: ")
ERROR_CASES = [
    ("bodies.0.orbit.e", -0.1, "bodies[0] (a).orbit.e: expected 0 <= e, got -0.1"),
    ("bodies.0.orbit.e", NAN, "bodies[0] (a).orbit.e: expected a number (finite), got nan"),
    ("bodies.0.orbit.e", float("inf"), "bodies[0] (a).orbit.e: expected a number (finite), got inf"),
    ("bodies.0.orbit.e", "big", 'bodies[0] (a).orbit.e: expected a number, got "big"'),
    ("bodies.0.orbit.a", "7000 kg", 'bodies[0] (a).orbit.a: expected a length, e.g. "7000 km" (got a quantity in kg), got "7000 kg"'),
    ("bodies.0.orbit.a", "7000", 'bodies[0] (a).orbit.a: expected a length, e.g. "7000 km" (got a number without a unit), got "7000"'),
    ("bodies.0.orbit.a", "nan km", 'bodies[0] (a).orbit.a: expected a length, e.g. "7000 km" (finite), got "nan km"'),
    ("bodies.0.orbit.a", "1e400 km", 'bodies[0] (a).orbit.a: expected a length, e.g. "7000 km" (finite), got "1e400 km"'),
    ("bodies.0.orbit.a", 10**400, 'bodies[0] (a).orbit.a: expected a length, e.g. "7000 km" (finite), got an integer of 401 digits'),
    ("bodies.0.orbit.a", True, 'bodies[0] (a).orbit.a: expected a length, e.g. "7000 km", got true'),
    ("bodies.0.orbit.a", "-7000 km", 'bodies[0] (a).orbit.a: expected a > 0 for an ellipse (e < 1), got "-7000 km"'),
    ("bodies.0.orbit.i", "181 deg", 'bodies[0] (a).orbit.i: expected 0 <= i <= 180 deg, got "181 deg"'),
    ("bodies.0.orbit.i", 30, 'bodies[0] (a).orbit.i: expected an angle in rad (bare numbers are SI) or with a unit like "30 deg", got 30'),
    ("bodies.0.orbit.raan", "10 m", 'bodies[0] (a).orbit.raan: expected an angle, e.g. "51.6 deg" (got a quantity in m), got "10 m"'),
    ("bodies.0.orbit.ecc", 0.1, 'bodies[0] (a).orbit.ecc: expected one of the keys model, r, v, a, p, rp, e, i, raan, argp, nu, M, degree, perturbers (did you mean "e"?), got unknown key "ecc"'),
    ("bodies.0.orbit.model", "keppler", 'bodies[0] (a).orbit.model: expected one of kepler, j2, zonal, third_body (did you mean "kepler"?), got "keppler"'),
    ("bodies.0.orbit.M", "10 deg", 'bodies[0] (a).orbit.M: expected either nu or M, not both, got "10 deg"'),
    ("bodies.0.orbit.p", "7000 km", "bodies[0] (a).orbit: expected exactly one of a, p, rp (the size of the conic), got a, p"),
    ("bodies.0.orbit.r", [1, 0, 0], 'bodies[0] (a).orbit.a: expected either a state vector (r, v) or elements, not both, got "7000 km"'),
    ("bodies.0.orbit.degree", 4, 'bodies[0] (a).orbit.degree: expected no degree unless model = "zonal", got 4'),
    ("bodies.0.orbit.perturbers", ["moon"], 'bodies[0] (a).orbit.perturbers: expected no perturbers unless model = "third_body", got ["moon"]'),
    ("bodies.1.orbit.r", ["0 km", "0 km", "0 km"], 'bodies[1] (b).orbit.r: expected |r| > 0 (not at the centre of the central body), got ["0 km", "0 km", "0 km"]'),
    ("bodies.1.orbit.r", ["1 km", "2 km"], 'bodies[1] (b).orbit.r: expected a list of 3 values, each a length, e.g. "7000 km", got ["1 km", "2 km"]'),
    ("bodies.1.orbit.v", ["1 km", "0 km/s", "0 km/s"], 'bodies[1] (b).orbit.v[0]: expected a speed, e.g. "7.5 km/s" (got a quantity in km), got "1 km"'),
    ("bodies.1.orbit", {}, "bodies[1] (b).orbit: expected a state vector (r, v) or elements (a | p | rp, e, i, raan, argp, nu | M), got neither"),
    ("bodies.1.orbit", 5, "bodies[1] (b).orbit: expected a table, got 5"),
    ("bodies.0.attitude.inertia", [1, 1, 3], "bodies[0] (a).attitude.inertia: expected principal moments obeying the triangle inequality (each <= the sum of the other two), got [1.0, 1.0, 3.0]"),
    ("bodies.0.attitude.inertia", [1, 0, 1], "bodies[0] (a).attitude.inertia: expected positive principal moments (a singular or negative inertia is not a rigid body), got [1.0, 0.0, 1.0]"),
    ("bodies.0.attitude.inertia", [-1, 2, 2], "bodies[0] (a).attitude.inertia: expected positive principal moments (a singular or negative inertia is not a rigid body), got [-1.0, 2.0, 2.0]"),
    ("bodies.0.attitude.inertia", [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]], "bodies[0] (a).attitude.inertia: expected a symmetric tensor (I[i][j] = I[j][i]), got [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]]"),
    ("bodies.0.attitude.inertia", [[1, 2, 0], [2, 1, 0], [0, 0, 1]], "bodies[0] (a).attitude.inertia: expected positive principal moments (a singular or negative inertia is not a rigid body), got [-1.0, 1.0, 3.0]"),
    ("bodies.0.attitude.inertia", ["1 kg", "1 kg m2", "1 kg m2"], 'bodies[0] (a).attitude.inertia[0]: expected a moment of inertia, e.g. "100 kg m2" (got a quantity in kg), got "1 kg"'),
    ("bodies.0.attitude.q", [1, 1, 0, 0], "bodies[0] (a).attitude.q: expected a unit quaternion, scalar first (| |q| - 1 | <= 1e-06; |q| = 1.41421356), got [1, 1, 0, 0]"),
    ("bodies.0.attitude.q", [0, 0, 0, 0], "bodies[0] (a).attitude.q: expected a unit quaternion, scalar first (| |q| - 1 | <= 1e-06; |q| = 0), got [0, 0, 0, 0]"),
    ("bodies.0.attitude.euler", [0, 0, 0], "bodies[0] (a).attitude.euler: expected either q or euler (+ seq), not both, got [0, 0, 0]"),
    ("bodies.0.attitude.seq", "321", 'bodies[0] (a).attitude.seq: expected seq only together with euler, got "321"'),
    ("bodies.2.attitude.seq", "324", 'bodies[2] (c).attitude.seq: expected one of 121, 123, 131, 132, 212, 213, 231, 232, 312, 313, 321, 323 (did you mean "323"?), got "324"'),
    ("bodies.2.attitude.seq", DELETE, "bodies[2] (c).attitude.seq: expected a rotation sequence with euler, one of 121, 123, 131, 132, 212, 213, 231, 232, 312, 313, 321, 323, got nothing"),
    ("bodies.0.attitude.w", ["1 rad", 0, 0], 'bodies[0] (a).attitude.w[0]: expected an angular velocity, e.g. "0.1 rad/s" (got a quantity in rad), got "1 rad"'),
    ("bodies.0.attitude.model", "torquefree", 'bodies[0] (a).attitude.model: expected one of none, torque_free, gravity_gradient, gyrostat, heavy_top, user, flexible, rolling_disk (did you mean "torque_free"?), got "torquefree"'),
    ("bodies.0.attitude.mass", "1 kg", 'bodies[0] (a).attitude.mass: expected no mass unless model = "heavy_top" or "flexible", got "1 kg"'),
    ("bodies.0.attitude.rotors", [{"axis": [0, 0, 0], "h": 1.0}], "bodies[0] (a).attitude.rotors[0].axis: expected a non-zero axis (body components; normalized on load), got [0, 0, 0]"),
    ("bodies.0.attitude.rotors", [{"axis": [0, 0, 1], "h": 1.0, "speed": 2.0}], "bodies[0] (a).attitude.rotors[0].h: expected either h or speed + inertia, not both, got 1.0"),
    ("bodies.0.attitude.rotors", [{"axis": [0, 0, 1], "speed": 2.0, "inertia": -1.0}], "bodies[0] (a).attitude.rotors[0].inertia: expected inertia > 0 (axial moment of the rotor), got -1.0"),
    ("bodies.0.attitude.rotors", [{"axis": [0, 0, 1], "hh": 1.0}], 'bodies[0] (a).attitude.rotors[0].hh: expected one of the keys axis, h, speed, inertia (did you mean "h"?), got unknown key "hh"'),
    ("bodies.2.attitude.inertia", DELETE, "bodies[2] (c).attitude.inertia: expected the inertia (3 principal moments or a 3x3 tensor) for model torque_free, got nothing"),
    ("bodies.2.attitude.model", "gravity_gradient", 'bodies[2] (c).attitude.model: expected an orbit table with gravity_gradient (the torque depends on the position), got "gravity_gradient" without an orbit'),
    ("bodies.2.attitude.model", "gyrostat", "bodies[2] (c).attitude.rotors: expected at least one rotor for model gyrostat, got none"),
    ("bodies.2.attitude.model", "heavy_top", "bodies[2] (c).attitude.mass: expected a value (required), got nothing"),
    ("bodies.2.cross_check", True, "bodies[2] (c).cross_check: expected an orbit to cross-check, got true without an orbit"),
    ("bodies.1.cross_check", "yes", 'bodies[1] (b).cross_check: expected true or false, got "yes"'),
    ("bodies.1.name", "a", 'bodies[1].name: expected a unique body name (also bodies[0]), got "a"'),
    ("bodies.1.name", "a/b", 'bodies[1].name: expected a name matching [A-Za-z0-9_.-]{1,128}, got "a/b"'),
    ("bodies.1.name", "@status", 'bodies[1].name: expected a name matching [A-Za-z0-9_.-]{1,128}, got "@status"'),
    ("bodies.1.name", DELETE, "bodies[1].name: expected a value (required), got nothing"),
    ("bodies.1.orbit", DELETE, 'bodies[1] (b): expected an orbit table, an attitude table or both, got body "b" with neither'),
    ("bodies", [], "bodies: expected at least one body ([[bodies]] or [walker]), got none"),
    ("bodies", {"name": "x"}, "bodies: expected an array of tables [[bodies]], got a table"),
    ("scenario.duration", "0 s", 'scenario.duration: expected duration > 0, got "0 s"'),
    ("scenario.duration", "-5 min", 'scenario.duration: expected duration > 0, got "-5 min"'),
    ("scenario.duration", "2000 yr", 'scenario.duration: expected duration <= 250 years, got "2000 yr"'),
    ("scenario.duration", "10 m", 'scenario.duration: expected a time, e.g. "90 min" (got a quantity in m), got "10 m"'),
    ("scenario.rate", "1 MHz", 'scenario.rate: expected 1e-06 Hz <= rate <= 1000 Hz, got "1 MHz"'),
    ("scenario.rate", 0, "scenario.rate: expected 1e-06 Hz <= rate <= 1000 Hz, got 0"),
    ("scenario.rate", "10 s", 'scenario.rate: expected a rate, e.g. "10 Hz" (got a quantity in s), got "10 s"'),
    # the wrong kind of unit is named, also when every word of it is known (probe A, F12)
    ("scenario.duration", "90 kg", 'scenario.duration: expected a time, e.g. "90 min" (got a quantity in kg), got "90 kg"'),
    ("scenario.rate", "1 per minutes per sec", 'scenario.rate: expected a rate, e.g. "10 Hz" (got a quantity in 1 / s2), '
                                               'got "1 per minutes per sec"'),
    # digit groups: astropy read "5 400 s" as 5 x (a unit 400 s long) = 2000 s (probe A, F4)
    ("scenario.duration", "5 400 s", 'scenario.duration: expected a time, e.g. "90 min" (a number after the value ("400" '
                                     'after "5") would scale the unit; write numbers without spaces between digit groups, '
                                     'e.g. "5400 s"), got "5 400 s"'),
    ("bodies.0.orbit.a", "7 000 km", 'bodies[0] (a).orbit.a: expected a length, e.g. "7000 km" (a number after the value '
                                     '("000" after "7") would scale the unit; write numbers without spaces between digit '
                                     'groups, e.g. "7000 km"), got "7 000 km"'),
    ("bodies.1.orbit.r", "[6 978.137, 0, 0] km", 'bodies[1] (b).orbit.r[0]: expected a length, e.g. "7000 km" (a number '
                                                 'after the value ("978.137" after "6") would scale the unit; write numbers '
                                                 'without spaces between digit groups, e.g. "6978.137 km"), got "6 978.137 km"'),
    ("scenario.real_time_factor", 0, "scenario.real_time_factor: expected 0 < real_time_factor <= 1e+06, got 0"),
    ("scenario.epoch", "yesterday", 'scenario.epoch: expected an epoch like "2026-03-20T12:00:00 TDB" (scales: UTC, TAI, TT, TDB, TCG, TCB, UT1), got "yesterday"'),
    ("scenario.epoch", "2026-03-20T12:00:00 GMT", 'scenario.epoch: expected an epoch like "2026-03-20T12:00:00 TDB" (scales: UTC, TAI, TT, TDB, TCG, TCB, UT1), got "2026-03-20T12:00:00 GMT"'),
    ("scenario.epoch", "1960-01-01T00:00:00", 'scenario.epoch: expected an epoch after 1970-01-01 and before 2262 (ns since 1970 must fit an int64), got "1960-01-01T00:00:00"'),
    ("scenario.epoch", "9999-01-01T00:00:00", 'scenario.epoch: expected an epoch after 1970-01-01 and before 2262 (ns since 1970 must fit an int64), got "9999-01-01T00:00:00"'),
    ("scenario.epoch", "2026-02-30T00:00:00", 'scenario.epoch: expected an epoch like "2026-03-20T12:00:00 TDB" (scales: UTC, TAI, TT, TDB, TCG, TCB, UT1) that astropy can convert offline, got "2026-02-30T00:00:00" (ValueError: '),
    ("scenario.epoch", 2026, 'scenario.epoch: expected an epoch like "2026-03-20T12:00:00 TDB" (scales: UTC, TAI, TT, TDB, TCG, TCB, UT1), got 2026'),
    ("scenario.name", "a b", 'scenario.name: expected a name matching [A-Za-z0-9_.-]{1,128}, got "a b"'),
    ("scenario.nmae", "x", 'scenario.nmae: expected one of the keys name, description, epoch, duration, rate, real_time_factor, frame (did you mean "name"?), got unknown key "nmae"'),
    ("scenario", DELETE, "scenario: expected a value (required), got nothing"),
    ("bodys", [], 'bodys: expected one of the keys scenario, central_body, bodies, walker, output, control (did you mean "bodies"?), got unknown key "bodys"'),
    ("central_body.name", "eart", 'central_body.name: expected one of earth, moon, sun, mars, venus, jupiter (did you mean "earth"?), or mu and radius given explicitly, got "eart"'),
    ("central_body.mu", "-1 m3/s2", 'central_body.mu: expected mu > 0, got "-1 m3/s2"'),
    ("central_body.j2", 2.0, "central_body.j2: expected |j2| < 1 (an unnormalized zonal coefficient), got 2.0"),
    ("output.path", "http://example.com/x.mcap", 'output.path: expected a file path (resolved relative to the config file), not a URL, got "http://example.com/x.mcap"'),
    ("output.path", "file:///tmp/x.mcap", 'output.path: expected a file path (resolved relative to the config file), not a URL, got "file:///tmp/x.mcap"'),
    ("output.roll_size", "10 kB", 'output.roll_size: expected 1 MiB <= roll_size <= 1 PiB, got "10 kB"'),
    # probe C (session 20): a body named as the scene's frame was its own parent in the 3D views
    ("bodies.0.name", "GCRF", "bodies[0].name: expected a body name other than the scene's frame 'GCRF' (a body's "
                              'frame in the live view and the Foxglove export would be its own parent), got "GCRF"'),
    # b is bit, B is byte: "256 mb" was read as millibits (4 bytes) and "256 Mb" as megabits (32 MB), never what was meant
    ("output.roll_size", "256 mb", 'output.roll_size: expected a size, e.g. "256 MB" (unit mbit counts bits, not bytes: b is '
                                   'bit, B is byte, and unit symbols are case-sensitive; accepted: byte, kB, MB, GB, KiB, MiB, '
                                   'GiB), got "256 mb"'),
    ("output.roll_size", "2048 Mb", 'output.roll_size: expected a size, e.g. "256 MB" (unit Mbit counts bits, not bytes: b is '
                                    'bit, B is byte, and unit symbols are case-sensitive; accepted: byte, kB, MB, GB, KiB, MiB, '
                                    'GiB), got "2048 Mb"'),
    ("output.roll_size", "2e9 mB", 'output.roll_size: expected a size, e.g. "256 MB" (unit mbyte is a fraction of a byte; '
                                   'accepted: byte, kB, MB, GB, KiB, MiB, GiB), got "2e9 mB"'),
]


@pytest.mark.parametrize("path,value,expected", ERROR_CASES, ids=[f"{i}-{c[0]}" for i, c in enumerate(ERROR_CASES)])
def test_every_error_path_names_the_field(path, value, expected):
    d = _set(base(), path, value)
    with pytest.raises(ScenarioError) as info:
        load(d)
    if expected.endswith("(ValueError: "):  # astropy's own text follows; not ours to pin
        assert str(info.value).startswith("configs/x.toml: " + expected)
    else:
        assert str(info.value) == "configs/x.toml: " + expected


HYPERBOLA_AND_WALKER_ERRORS = [
    ({"name": "x", "orbit": {"a": "7000 km", "e": 1.5}}, 'bodies[0] (x).orbit.a: expected a < 0 for a hyperbola (e > 1), got "7000 km"'),
    ({"name": "x", "orbit": {"a": "7000 km", "e": 1.0}}, 'bodies[0] (x).orbit.a: expected p or rp for a parabola (e = 1: a is infinite), got "7000 km"'),
    ({"name": "x", "orbit": {"rp": "7000 km", "e": 2.0, "nu": "130 deg"}}, 'bodies[0] (x).orbit.nu: expected |nu| < 120 deg (between the asymptotes of e = 2.0), got "130 deg"'),
    ({"name": "x", "orbit": {"rp": "7000 km", "e": 2.0, "model": "third_body", "perturbers": ["earth"]}}, 'bodies[0] (x).orbit.perturbers[0]: expected a body other than the central body, got "earth"'),
    ({"name": "x", "orbit": {"rp": "7000 km", "model": "zonal", "degree": 9}}, "bodies[0] (x).orbit.degree: expected an integer 2 <= n <= 6, got 9"),
    ({"name": "x", "orbit": {"rp": "7000 km"}, "attitude": {"model": "heavy_top", "inertia": [1, 1, 1], "mass": 1, "cm": 0.1}},
     "bodies[0] (x).orbit: expected no orbit for a heavy_top body (a top spins about a fixed point in uniform gravity), got an orbit table"),
]


@pytest.mark.parametrize("body,expected", HYPERBOLA_AND_WALKER_ERRORS)
def test_more_orbit_errors(body, expected):
    d = base()
    d["bodies"] = [body]
    with pytest.raises(ScenarioError) as info:
        load(d)
    assert str(info.value) == "configs/x.toml: " + expected


WALKER = {"i": "53 deg", "t": 12, "p": 3, "f": 1, "altitude": "550 km"}


@pytest.mark.parametrize(
    "change,expected",
    [
        ({"p": 5}, "walker.p: expected a divisor of t = 12 (equal planes), got 5"),
        ({"f": 3}, "walker.f: expected an integer 0 <= n <= 2, got 3"),
        ({"t": 0}, "walker.t: expected an integer 1 <= n <= 100000, got 0"),
        ({"t": 2.5}, "walker.t: expected an integer 1 <= n <= 100000, got 2.5"),
        ({"a": "7000 km"}, "walker: expected exactly one of altitude, a, got both"),
        ({"altitude": "-7000 km"}, 'walker.altitude: expected an orbit radius a > 0, got "-7000 km"'),
        ({"prefix": "a"}, 'walker.prefix: expected a unique body name (also bodies[0]), got "a-0-0"'),
        ({"planes": 3}, 'walker.planes: expected one of the keys prefix, i, t, p, f, altitude, a, raan0, model, cross_check, attitude (did you mean "p"?), got unknown key "planes"'),
    ],
)
def test_walker_errors(change, expected):
    d = base()
    d["bodies"] = [{"name": "a-0-0", "orbit": {"rp": "7000 km"}}]
    d["walker"] = dict(WALKER, **change)
    with pytest.raises(ScenarioError) as info:
        load(d)
    assert str(info.value) == "configs/x.toml: " + expected


def test_file_level_errors(tmp_path):
    with pytest.raises(ScenarioError, match=r"^.*nope\.toml: file: expected a readable TOML file, got FileNotFoundError"):
        S.load(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_bytes(b"\xff\xfe")
    with pytest.raises(ScenarioError, match=r"bad\.toml: file: expected UTF-8 text, got invalid byte at offset 0$"):
        S.load(bad)
    bad.write_text("[scenario\nname = 1")
    with pytest.raises(ScenarioError, match=r"bad\.toml: toml: expected valid TOML, got "):
        S.load(bad)
    with pytest.raises(ScenarioError, match=r"^<string>: toml: expected valid TOML"):
        S.loads("x = [" * 5000)


def test_cli_validate(tmp_path, capsys):
    demo = next(p for p in CONFIGS if p.stem == "demo")
    assert S.main([str(demo)]) == 0
    out = capsys.readouterr().out
    assert "ok" in out and "processes: orbit, attitude, logger" in out and "kepler" in out
    bad = tmp_path / "bad.toml"
    bad.write_text(to_toml(_set(base(), "bodies.0.orbit.e", -0.1)))
    assert S.main([str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.strip() == f"astrodyn validate: {bad}: bodies[0] (a).orbit.e: expected 0 <= e, got -0.1"
    assert S.main([str(demo), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["name"] == "demo"


def test_toml_writer_round_trips_the_base_config():
    import tomllib

    assert tomllib.loads(to_toml(base())) == base()


# --------------------------------------------------------------------------- fuzz

FUZZ_SECONDS = 5.0  # per example: astropy parsing is the slowest step, ~1 ms per quantity


def _load_text_never_fails_otherwise(text: str) -> None:
    t0 = time.perf_counter()
    try:
        scn = S.loads(text, source="fuzz.toml")
    except ScenarioError as exc:
        assert str(exc).startswith("fuzz.toml: ")
    else:
        assert isinstance(scn, S.Scenario)
        S.plan(scn)
        json.dumps(scn.to_dict(), allow_nan=False)
    assert time.perf_counter() - t0 < FUZZ_SECONDS


toml_chars = st.text(alphabet=st.sampled_from(list("[]{}=\"'.,#\n abcdeinopqrstuvwxyz0123456789-_+:T")), max_size=200)


@settings(max_examples=150, suppress_health_check=[HealthCheck.too_slow])
@given(toml_chars)
def test_fuzz_random_text(text):
    _load_text_never_fails_otherwise(text)


@settings(max_examples=50)
@given(st.binary(max_size=200))
def test_fuzz_random_bytes_file(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("fz") / "f.toml"
    path.write_bytes(data)
    try:
        S.load(path)
    except ScenarioError:
        pass


scalar_values = st.one_of(
    st.none(), st.booleans(), st.integers(-10**6, 10**6), st.integers(), st.floats(),
    st.sampled_from(["7000 km", "-1 km", "0 s", "10 Hz", "51.6 deg", "1 kg", "nan km", "inf s", "1e400 km", "", "x",
                     "321", "kepler", "j2", "third_body", "torque_free", "gyrostat", "heavy_top", "user", "none",
                     "2026-03-20T12:00:00 TDB", "[1, 2, 3] km", "[1, 2] m", "1/0 s", "0.3 AU", "60 rpm"]),
    st.text(max_size=12),
)
values = st.recursive(scalar_values, lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.sampled_from(["a", "e", "h", "axis", "name", "x"]), inner, max_size=3)), max_leaves=8)

_PATHS = [
    "scenario.name", "scenario.epoch", "scenario.duration", "scenario.rate", "scenario.real_time_factor", "scenario.frame",
    "central_body.name", "central_body.mu", "central_body.radius", "central_body.j2",
    "bodies.0.name", "bodies.0.orbit.a", "bodies.0.orbit.e", "bodies.0.orbit.i", "bodies.0.orbit.nu", "bodies.0.orbit.M",
    "bodies.0.orbit.model", "bodies.0.orbit.p", "bodies.0.orbit.rp", "bodies.0.orbit.degree", "bodies.0.orbit.perturbers",
    "bodies.0.attitude.q", "bodies.0.attitude.w", "bodies.0.attitude.inertia", "bodies.0.attitude.model",
    "bodies.0.attitude.rotors", "bodies.0.attitude.mass", "bodies.0.attitude.cm", "bodies.0.attitude.torque",
    "bodies.1.orbit.r", "bodies.1.orbit.v", "bodies.1.orbit.model", "bodies.1.cross_check", "bodies.1.name",
    "bodies.2.attitude.euler", "bodies.2.attitude.seq", "bodies.2.attitude.model",
    "walker.t", "walker.p", "walker.f", "walker.i", "walker.altitude", "walker.model",
    "output.path", "output.roll_size", "unknown.key", "bodies.0.extra",
]


@st.composite
def mutated_configs(draw):
    d = base()
    if draw(st.booleans()):
        d["walker"] = dict(WALKER)
    for _ in range(draw(st.integers(1, 4))):
        path = draw(st.sampled_from(_PATHS))
        value = DELETE if draw(st.integers(0, 5)) == 0 else draw(values)
        try:
            _set(d, path, value)
        except (KeyError, IndexError, TypeError, AttributeError):
            pass  # the path no longer exists after an earlier mutation
    return d


@settings(max_examples=200, suppress_health_check=[HealthCheck.too_slow])
@given(mutated_configs())
def test_fuzz_mutated_configs(d):
    # through the dict loader (None / odd values allowed) ...
    t0 = time.perf_counter()
    try:
        S.load_dict(d, source="fuzz.toml")
    except ScenarioError as exc:
        assert str(exc).startswith("fuzz.toml: ")
    assert time.perf_counter() - t0 < FUZZ_SECONDS
    # ... and through real TOML text when the mutation is expressible in TOML
    try:
        text = to_toml(d)
    except TypeError:
        return
    _load_text_never_fails_otherwise(text)


def test_plan_names_state_and_cross_check_messages_apart():
    """The header of a run counts what the logger will count: states (orbit + attitude)
    and, separately, the REBOUND cross-checks (per body in the config, or all orbits with
    ``run --cross-check``).  Independent count: steps x channels of each kind."""
    d = base()
    scn = load(d)
    n = scn.n_steps
    p = S.plan(scn)
    orbits = sum(b.orbit is not None for b in scn.bodies)
    attitudes = sum(b.attitude is not None for b in scn.bodies)
    assert p.crosscheck_messages == 0 and p.state_messages == p.messages == n * (orbits + attitudes)
    q = S.plan(scn, cross_check_all=True)
    assert q.crosscheck_messages == n * orbits and q.state_messages == p.state_messages
    assert f"{q.state_messages} state messages (orbit + attitude) + {q.crosscheck_messages} cross-check messages" in q.text()
