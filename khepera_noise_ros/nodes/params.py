"""Parameter declarations for the nodes, and the core objects built from them.

Each node lists its parameters once as ``Spec`` rows; ``declare`` gives every
one a ParameterDescriptor with a description and, where numeric, a range, so
``ros2 param describe`` documents the node and rclpy refuses out-of-range values
before our own checks run.  ``world_from``/``noise_from``/``task_from`` turn a
dict of parameter values into core objects, raising the core's ValueError
(which names the value and what is allowed) for the node to hand back as the
reason a set was refused.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Iterable

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

from ..core.khepera import World
from ..core.noise import DISTRIBUTIONS, MODELS, NoiseModel, parse_groups
from ..core.task import Task

SEED_MAX = 2 ** 53 - 1                  # seeds travel as float64 in episode_start


@dataclass(frozen=True)
class Spec:
    """One parameter: name, default (its type is the parameter's type), documentation."""

    name: str
    default: Any
    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()
    type_: Parameter.Type | None = None     # needed only where the default is an empty list
    read_only: bool = False

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(name=self.name, description=self.description,
                                read_only=self.read_only)
        if self.choices:
            d.additional_constraints = 'one of: ' + ', '.join(self.choices)
        if self.low is not None and isinstance(self.default, float):
            d.floating_point_range = [FloatingPointRange(
                from_value=float(self.low), to_value=float(self.high), step=0.0)]
        elif self.low is not None and isinstance(self.default, int):
            d.integer_range = [IntegerRange(
                from_value=int(self.low), to_value=int(self.high), step=1)]
        return d


def declare(node: Node, specs: Iterable[Spec]) -> None:
    """Declare every spec; an empty-list default is declared by type, then set to []."""
    for spec in specs:
        if spec.type_ is not None:
            node.declare_parameter(spec.name, spec.type_, spec.descriptor())
            if node.get_parameter_or(spec.name).type_ == Parameter.Type.NOT_SET:
                node.set_parameters([Parameter(spec.name, spec.type_, spec.default)])
        else:
            node.declare_parameter(spec.name, spec.default, spec.descriptor())


def current(node: Node, specs: Iterable[Spec]) -> dict[str, Any]:
    return {s.name: node.get_parameter(s.name).value for s in specs}


def proposed(node: Node, specs: Iterable[Spec], params: list[Parameter]) -> dict[str, Any]:
    """The values the node would have if ``params`` were accepted."""
    values = current(node, specs)
    values.update({p.name: p.value for p in params if p.name in values})
    return values


def overrides(specs: Iterable[Spec], values: dict[str, Any] | None) -> list[Parameter]:
    """parameter_overrides for a node from a plain dict; ints become floats where needed."""
    by_name = {s.name: s for s in specs}
    unknown = sorted(set(values or ()) - set(by_name))
    if unknown:
        raise ValueError(f'unknown parameter(s) {unknown}; known: {sorted(by_name)}')
    out = []
    for name, value in (values or {}).items():
        spec = by_name[name]
        if isinstance(spec.default, float) and isinstance(value, int):
            value = float(value)
        elif spec.type_ == Parameter.Type.DOUBLE_ARRAY:
            value = [float(v) for v in value]
        out.append(Parameter(name, spec.type_ or Parameter.Type.from_parameter_value(value),
                             value))
    return out


def check_choice(name: str, value: str, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ValueError(f'{name} must be one of {choices}, got {value!r}')


# --- core objects from parameter values ---------------------------------------------------

GEOMETRY = tuple(f.name for f in fields(World) if f.name != 'deg_per_power')


def world_from(values: dict[str, Any]) -> World:
    """A World from the geometry values present (deg_per_power only if given)."""
    return World(**{f.name: values[f.name] for f in fields(World) if f.name in values})


def noise_from(values: dict[str, Any]) -> NoiseModel:
    check_choice('noise_model', values['noise_model'], MODELS)
    check_choice('distribution', values['distribution'], DISTRIBUTIONS)
    return NoiseModel(model=values['noise_model'], dependent=values['dependent_level'],
                      independent=values['independent_level'],
                      groups=parse_groups(values['dependence_groups']),
                      distribution=values['distribution'])


def task_from(values: dict[str, Any]) -> Task:
    return Task(steps=values['steps'], perturb_every=values['perturb_every'],
                perturbation_deg=values['perturbation_deg'])


_WORLD = World()
_TASK = Task()

# Geometry is shared by every robot node: for a hardware bridge it declares the world the
# robot stands in, so recordings and fitness can be compared with the simulator's.
GEOMETRY_SPECS = (
    Spec('lamp_distance_mm', _WORLD.lamp_distance_mm, 'Distance from the robot to the lamp, mm.',
         0.0, 1e4),
    Spec('ambient', _WORLD.ambient, 'Reading of a sensor that sees no lamp (0 bright, 525 dark).',
         0.0, 525.0),
    Spec('gain', _WORLD.gain, 'Largest drop in reading a lamp on the sensor axis causes.',
         0.0, 525.0),
    Spec('reach_mm', _WORLD.reach_mm, 'Distance at which the lamp stops lowering readings, mm.',
         1e-6, 1e4),
    Spec('half_angle_deg', _WORLD.half_angle_deg,
         'A sensor sees the lamp within this angle of its axis, degrees.', 0.0, 180.0),
    Spec('floor', _WORLD.floor, 'Brightest (lowest) reading a sensor can give.', 0.0, 525.0),
)

TASK_SPECS = (
    Spec('steps', _TASK.steps, 'Control steps per episode (the paper: 60).', 1, 100000),
    Spec('perturb_every', _TASK.perturb_every,
         'The heading is knocked every this many steps, step 0 included (the paper: 5).',
         1, 100000),
    Spec('perturbation_deg', _TASK.perturbation_deg,
         'Largest heading knock, degrees; each knock is uniform in +-this.', 0.0, 180.0),
)
