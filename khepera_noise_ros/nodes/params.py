"""Parameter declarations for the nodes, and the core objects built from them.

Each node lists its parameters once as ``Spec`` rows; ``declare`` gives every
one a ParameterDescriptor with a description and, where numeric, a range, so
``ros2 param describe`` documents the node and rclpy refuses out-of-range values
before our own checks run; it also guards the node's SetParameters services
(``guard_parameter_services``) so that no request can stop the node.
``world_from``/``noise_from``/``task_from`` turn a dict of parameter values into
core objects, raising the core's ValueError (which names the value and what is
allowed) for the node to hand back as the reason a set was refused.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Callable, Iterable

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, Parameter as ParameterMsg,
                                ParameterDescriptor, SetParametersResult)
from rcl_interfaces.srv import SetParameters, SetParametersAtomically
from rclpy.node import Node
from rclpy.parameter import Parameter

from ..core.khepera import World
from ..core.noise import DISTRIBUTIONS, MODELS, ROUNDINGS, NoiseModel, parse_groups
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
    """Declare every spec (an empty-list default is declared by type, then set to []) and
    guard the node's parameter services."""
    guard_parameter_services(node)
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
    """The values the node would have if ``params`` were accepted; a ValueError for a name
    the node never declared (rclpy lets an empty name through to the on-set callbacks,
    which would otherwise declare it) or one given twice (only the last would count)."""
    names = [p.name for p in params]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f'parameter(s) {twice} given more than once in one request')
    values = current(node, specs)
    for p in params:
        if p.name in values:
            values[p.name] = p.value
        elif not p.name or not node.has_parameter(p.name):
            raise ValueError(f'unknown parameter {p.name!r}; this node has {sorted(values)}')
    return values


# --- parameter services that refuse instead of crashing ----------------------------------

_TYPES = frozenset(t.value for t in Parameter.Type)


def guard_parameter_services(node: Node) -> None:
    """Make the node's SetParameters and SetParametersAtomically services refuse, with a
    reason, what would otherwise raise in the service callback and so stop the executor
    and every node on it: a type code rcl_interfaces does not define (rclpy raises
    ValueError on it), or any error while a request is checked and applied (logged)."""
    for service in node.services:
        if service.srv_type in (SetParameters, SetParametersAtomically) \
                and not getattr(service.callback, 'guarded', False):
            service.callback = _guarded(service.srv_type, service.callback, node)


def _refused(reason: str) -> SetParametersResult:
    return SetParametersResult(successful=False, reason=reason)


def _type_error(param: ParameterMsg) -> str:
    if param.value.type in _TYPES:
        return ''
    return (f'parameter {param.name!r} has type code {param.value.type}, which is not a '
            f'ParameterType (0..{max(_TYPES)})')


def _guarded(srv_type, serve: Callable, node: Node) -> Callable:
    def attempt(request) -> list[SetParametersResult]:
        """The original service's results for ``request``; a refusal if it raised."""
        try:
            response = serve(request, srv_type.Response())
        except Exception as exc:            # a bug must cost a refusal, never the node
            node.get_logger().error(f'{srv_type.__name__} request failed: {exc!r}')
            return [_refused(f'the node failed while setting it: {exc!r}')]
        return list(response.results) if srv_type is SetParameters else [response.result]

    def guarded(request, response):
        errors = [_type_error(p) for p in request.parameters]
        if srv_type is SetParametersAtomically:
            bad = [e for e in errors if e]
            response.result = _refused(bad[0]) if bad else attempt(request)[0]
            return response
        for param, error in zip(request.parameters, errors):    # one at a time, as rclpy
            response.results.extend([_refused(error)] if error else attempt(
                SetParameters.Request(parameters=[param])))
        return response
    guarded.guarded = True
    return guarded


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
    rounding = values.get('rounding', ROUNDINGS[0])     # nodes without the parameter
    check_choice('rounding', rounding, ROUNDINGS)
    return NoiseModel(model=values['noise_model'], dependent=values['dependent_level'],
                      independent=values['independent_level'],
                      groups=parse_groups(values['dependence_groups']),
                      distribution=values['distribution'], rounding=rounding)


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
