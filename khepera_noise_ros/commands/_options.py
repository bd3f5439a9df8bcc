"""What the commands share: UsageError, and the options for the noise model and the world."""
from __future__ import annotations

import argparse

from ..core.khepera import World
from ..core.noise import DEFAULT_GROUPS, DISTRIBUTIONS, MODELS, NoiseModel, format_groups, \
    parse_groups


class UsageError(Exception):
    """A mistake in the command line or its inputs, reported without a traceback."""


def add_noise_arguments(parser: argparse.ArgumentParser, model: str = 'combination',
                        dependent: float = 0.03, independent: float = 0.02) -> None:
    g = parser.add_argument_group('noise model (levels are fractions: 0.05 is 5%)')
    g.add_argument('--model', choices=MODELS, default=model)
    g.add_argument('--dependent', type=float, default=dependent, metavar='D',
                   help='dependent (shared) noise level d')
    g.add_argument('--independent', type=float, default=independent, metavar='I',
                   help='independent noise level i')
    g.add_argument('--groups', default=format_groups(DEFAULT_GROUPS), metavar='G',
                   help="dependence groups, e.g. '0,1,2;3,4,5'")
    g.add_argument('--distribution', choices=DISTRIBUTIONS, default='uniform')


def noise_from_args(args: argparse.Namespace) -> NoiseModel:
    return NoiseModel(args.model, args.dependent, args.independent,
                      parse_groups(args.groups), args.distribution)


def add_world_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group('world')
    g.add_argument('--lamp-distance', type=float, default=World.lamp_distance_mm,
                   metavar='MM', help='lamp distance from the sensors, mm')
    g.add_argument('--deg-per-power', type=float, default=World.deg_per_power,
                   help='rotation per control step per unit of power, degrees')


def world_from_args(args: argparse.Namespace) -> World:
    return World(lamp_distance_mm=args.lamp_distance, deg_per_power=args.deg_per_power)
