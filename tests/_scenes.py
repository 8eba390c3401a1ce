"""TOML parts of the test scenes that several scenes share, each written once.

Every function returns TOML text (ending in a newline) to be joined into a scene's text.
Values are written as the scene files take them: a ``str`` (quantity text such as "0.1 kg
m2" or "24000 rpm", or a name) in quotes, a number bare (SI units), an axis or a position,
a sequence of such values (body components), as a TOML array.

The ``[scenario]`` table and Kepler orbiters are :func:`_recordings.scenario_head` and
:func:`_recordings.orbiter`; the closed-loop detumble scene is
:func:`_by_hand_controller.detumble_scene`.
"""

from __future__ import annotations

import json
from collections.abc import Sequence


def toml_value(value) -> str:
    """``value`` as TOML: a string (quantity text, a name) in double quotes, a number bare, a
    sequence as an array of those (``[1, 0, 0]``, ``["0 m", "1 m", "0 m"]``)."""
    if isinstance(value, str | int | float):
        return json.dumps(value)
    return "[" + ", ".join(toml_value(v) for v in value) + "]"


def fault_table(t: str, fault: str, body: str = "sc", **keys) -> str:
    """A ``[[control.faults]]`` entry: ``fault`` of ``body`` at sim time ``t`` (quantity
    text), with the fault's own ``keys`` (e.g. ``sensor``, ``duration``, ``value``,
    ``wheel``) in the order given."""
    return (f"[[control.faults]]\nt = {toml_value(t)}\nbody = {toml_value(body)}\nfault = {toml_value(fault)}\n"
            + "".join(f"{key} = {toml_value(value)}\n" for key, value in keys.items()))


def wheel_tables(axes: Sequence[Sequence[float]], inertia, max_torque, max_speed,
                 speeds: Sequence[str] | None = None) -> str:
    """``[[bodies.actuators.wheels]]`` entries, one per spin axis in ``axes`` (body
    components), all with the same rotor: ``inertia`` (kg m^2), ``max_torque`` (N m) and
    ``max_speed`` (rad/s) as numbers or quantity text; ``speeds`` (quantity text, one per
    wheel): their initial speeds, else none given (the default, at rest)."""
    speeds = [None] * len(axes) if speeds is None else speeds
    return "".join(f"[[bodies.actuators.wheels]]\naxis = {toml_value(axis)}\ninertia = {toml_value(inertia)}\n"
                   f"max_torque = {toml_value(max_torque)}\nmax_speed = {toml_value(max_speed)}\n"
                   + ("" if speed is None else f"speed = {toml_value(speed)}\n")
                   for axis, speed in zip(axes, speeds, strict=True))


def tumbling_sc(actuators: str) -> str:
    """A ``[[bodies]]`` entry: body ``sc``, a rigid body tumbling at w = (0.01, -0.02, 0.03)
    rad/s with the full inertia tensor [[120, 2, -1], [2, 100, 0.5], [-1, 0.5, 80]] kg m^2 (no
    principal axis along a body axis), and the TOML ``actuators`` (e.g. :func:`wheel_tables`)
    in its ``[bodies.actuators]`` table."""
    return f"""[[bodies]]
name = "sc"
[bodies.attitude]
w = [0.01, -0.02, 0.03]
inertia = [[120, 2, -1], [2, 100, 0.5], [-1, 0.5, 80]]
[bodies.actuators]
{actuators}"""


#: The own keys of a ``type = "rate"`` gyroscope of :func:`gyro_table`: a 30 Hz gimbal
#: spring, damping ratio 0.7.
RATE_GYRO_DYNAMICS = 'natural_frequency = "30 Hz"\ndamping_ratio = 0.7\n'


def gyro_table(kind: str, input_axis: Sequence[float], own_keys: str,
               output_axis: Sequence[float] = (0, 1, 0)) -> str:
    """A ``[[bodies.gyros]]`` entry (after a blank line) of ``type = kind`` with its
    ``input_axis`` and ``output_axis`` (body components) and a rotor of spin inertia 1e-4
    kg m^2, transverse inertia 6e-5 kg m^2 at 24000 rpm; ``own_keys``: the TOML lines of its
    type's own keys (e.g. :data:`RATE_GYRO_DYNAMICS`)."""
    return f"""
[[bodies.gyros]]
type = "{kind}"
input_axis = {toml_value(input_axis)}
output_axis = {toml_value(output_axis)}
spin_inertia = "1e-4 kg m2"
transverse_inertia = "6e-5 kg m2"
spin_rate = "24000 rpm"
{own_keys}"""


def appendage_table(root: Sequence[str], normal: Sequence[float], length: str, mass_per_length: str,
                    bending_stiffness: str, modes: int, axis: Sequence[float] | None = None) -> str:
    """A ``[[bodies.attitude.appendages]]`` entry of a flexible body: a beam at ``root``
    (quantity texts, body axes) along ``axis`` (when None, not written: the config's default,
    the root's direction), bending in the plane of ``normal``, of ``length``,
    ``mass_per_length`` and ``bending_stiffness`` (quantity texts), with ``modes`` modes per
    plane."""
    return (f"[[bodies.attitude.appendages]]\nroot = {toml_value(root)}\n"
            + ("" if axis is None else f"axis = {toml_value(axis)}\n")
            + f"normal = {toml_value(normal)}\nlength = {toml_value(length)}\n"
              f"mass_per_length = {toml_value(mass_per_length)}\nbending_stiffness = {toml_value(bending_stiffness)}\n"
              f"modes = {modes}\n")


def coin_body(name: str, keys: str) -> str:
    """A ``[[bodies]]`` entry ``name``: a 2-euro coin rolling on a plane (``model =
    "rolling_disk"``, radius 12.9 mm, mass 8.5 g) with the further attitude ``keys`` (TOML
    lines: lean, heading, rates, ...)."""
    return f"""[[bodies]]
name = "{name}"
[bodies.attitude]
model = "rolling_disk"
radius = "12.9 mm"
mass = "8.5 g"
{keys}"""
