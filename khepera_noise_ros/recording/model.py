"""The recording in memory (``Recording``), its manifest and the checks both file formats share."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Mapping, TypeGuard

import numpy as np
import yaml
from numpy.typing import NDArray

if TYPE_CHECKING:
    from ..core.task import Trace

FORMAT = 'khepera-noise-recording/1'
KHEPERA_CHANNELS = 8
COLUMNS = ('episode', 'step', 'heading_deg', 'condition') + tuple(f's{i}' for i in range(8)) \
    + ('direction', 'power')
SOURCES = ('simulator', 'emulator', 'hardware')
PROTOCOLS = ('stationary', 'closed_loop')
KHEPERA_RANGE = (0.0, 525.0)


class RecordingError(ValueError):
    """A recording that breaks the format; the message names the file, line and problem."""


def columns(channels: int = KHEPERA_CHANNELS) -> tuple[str, ...]:
    """CSV header for ``channels`` light channels (the v1 layout for 8)."""
    return COLUMNS[:4] + tuple(f's{i}' for i in range(channels)) + COLUMNS[-2:]


@dataclass
class Recording:
    """Samples of C light channels (8 for a Khepera); NaN where a value is not known."""

    episode: NDArray[np.integer[Any]]       # (N,) int
    step: NDArray[np.integer[Any]]          # (N,) int
    heading_deg: NDArray[np.float64]        # (N,) NaN where unknown (closed loop on hardware)
    condition: NDArray[Any]                 # (N,) str, keys of manifest['conditions']
    readings: NDArray[np.float64]           # (N, C), 0 brightest .. 525 darkest on a Khepera
    direction: NDArray[np.float64]          # (N,) -1 left / +1 right, NaN in stationary data
    power: NDArray[np.float64]              # (N,) 0..9, NaN in stationary data
    manifest: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.episode.size)

    @property
    def channels(self) -> int:
        return int(self.readings.shape[1])

    @property
    def channels_used(self) -> list[int]:
        """Channels that carry data: the manifest's ``channels_used``, else all."""
        return list(self.manifest.get('channels_used', range(self.channels)))

    def select(self, mask: NDArray[Any]) -> 'Recording':
        """The rows where ``mask`` is true, with the same manifest."""
        return Recording(self.episode[mask], self.step[mask], self.heading_deg[mask],
                         self.condition[mask], self.readings[mask], self.direction[mask],
                         self.power[mask], self.manifest)

    def conditions(self) -> list[str]:
        """Condition labels in order of first appearance."""
        labels, first = np.unique(self.condition, return_index=True)
        return [str(labels[i]) for i in np.argsort(first)]

    def step_problems(self) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
        """(lost, duplicated) (episode, step) pairs: each step should appear exactly once.

        A step is lost when it is missing between 0 and the last step seen in its episode.
        """
        keys = self.episode.astype(np.int64) * (1 << 32) + self.step.astype(np.int64)
        unique, counts = np.unique(keys, return_counts=True)
        duplicated = [_split(k) for k in unique[counts > 1]]
        lost: list[tuple[int, int]] = []
        for e in np.unique(self.episode):
            seen = set(self.step[self.episode == e].tolist())
            lost += [(int(e), s) for s in range(max(seen) + 1) if s not in seen]
        return lost, duplicated

    def check(self) -> None:
        """Shapes, values and manifest, or a RecordingError naming the problem."""
        n = len(self)
        if self.readings.ndim != 2 or self.readings.shape[0] != n or self.channels < 1:
            raise RecordingError(f'readings must be ({n}, channels), got {self.readings.shape}')
        for name in ('step', 'heading_deg', 'condition', 'direction', 'power'):
            if getattr(self, name).shape != (n,):
                raise RecordingError(f'{name} must have shape ({n},), got '
                                     f'{getattr(self, name).shape}')
        try:
            check_manifest(self.manifest, self.channels, in_file=False)
        except ValueError as exc:
            raise RecordingError(f'manifest: {exc}') from None
        bad = first_bad_row(self)
        if bad:
            raise RecordingError(f'sample {bad[0]}: {bad[1]}')


def from_trace(trace: Trace, condition: str, manifest: dict[str, Any],
               first_episode: int = 0, stationary: bool = False) -> Recording:
    """Rows from a core ``Trace`` (arrays (steps, B, ...)): robot b is episode first + b.

    ``stationary`` leaves direction and power empty, as the format asks of
    recordings in which the robot did not act.
    """
    steps, robots = trace.power.shape
    by_robot: Callable[[NDArray[Any]], NDArray[np.float64]] = (
        lambda a: np.swapaxes(np.asarray(a, np.float64), 0, 1)
        .reshape(robots * steps, *np.shape(a)[2:]))
    empty = np.full(robots * steps, np.nan)
    return Recording(
        episode=np.repeat(np.arange(robots) + first_episode, steps),
        step=np.tile(np.arange(steps), robots), heading_deg=by_robot(trace.bearing_deg),
        condition=np.full(robots * steps, condition), readings=by_robot(trace.readings),
        direction=empty if stationary else by_robot(trace.direction),
        power=empty if stationary else by_robot(trace.power), manifest=manifest)


def concatenate(recordings: list[Recording], manifest: dict[str, Any] | None = None
                ) -> Recording:
    """One recording from several, in order; the manifest's conditions are merged."""
    if not recordings:
        raise ValueError('nothing to concatenate')
    if manifest is None:
        manifest = dict(recordings[0].manifest)
        manifest['conditions'] = {k: v for r in recordings
                                  for k, v in r.manifest.get('conditions', {}).items()}
    join: Callable[[str], NDArray[Any]] = (
        lambda name: np.concatenate([getattr(r, name) for r in recordings]))
    return Recording(join('episode'), join('step'), join('heading_deg'), join('condition'),
                     join('readings'), join('direction'), join('power'), manifest)


def _split(key: int) -> tuple[int, int]:
    return int(key) >> 32, int(key) & 0xFFFFFFFF


# -- manifest -----------------------------------------------------------------------------

def check_manifest(manifest: object, channels: int, in_file: bool = True) -> None:
    """Raise ValueError naming the first manifest key that breaks the format.

    In a file, any channel count but 8 must be declared; in memory the data says it.
    """
    if not isinstance(manifest, dict):
        raise ValueError(f'the manifest must be a mapping, got {type(manifest).__name__}')
    if manifest.get('format') != FORMAT:
        raise ValueError(f'format must be {FORMAT!r}, got {manifest.get("format")!r}')
    if manifest.get('source') not in SOURCES:
        raise ValueError(f'source must be one of {SOURCES}, got {manifest.get("source")!r}')
    period = manifest.get('sample_period_s')
    if not _is_number(period) or not period > 0:
        raise ValueError(f'sample_period_s must be a positive number, got {period!r}')
    conditions = manifest.get('conditions')
    if not isinstance(conditions, dict) or not conditions \
            or not all(isinstance(k, str) and k for k in conditions):
        raise ValueError(f'conditions must map non-empty labels to world parameters, '
                         f'got {conditions!r}')
    if 'protocol' in manifest and manifest['protocol'] not in PROTOCOLS:
        raise ValueError(f'protocol must be one of {PROTOCOLS}, got {manifest["protocol"]!r}')
    declared = manifest.get('channels', KHEPERA_CHANNELS if in_file else channels)
    if declared != channels:
        raise ValueError(f'channels is {declared!r} but the data has {channels} channels')
    used = manifest.get('channels_used', list(range(channels)))
    if not isinstance(used, list) or not used or len(set(used)) != len(used) \
            or not all(isinstance(c, int) and 0 <= c < channels for c in used):
        raise ValueError(f'channels_used must list distinct channels 0..{channels - 1}, '
                         f'got {used!r}')
    if 'genome' in manifest and (not isinstance(manifest['genome'], list)
                                 or not all(_is_number(g) for g in manifest['genome'])):
        raise ValueError('genome must be a list of numbers')
    samples = manifest.get('samples', 0)
    if not isinstance(samples, int) or isinstance(samples, bool) or samples < 0:
        raise ValueError(f'samples must be a count >= 0, got {samples!r}')
    lost = manifest.get('lost_steps', [])
    if not isinstance(lost, list) or not all(
            isinstance(p, (list, tuple)) and len(p) == 2
            and all(isinstance(v, int) and v >= 0 for v in p)
            for p in lost):
        raise ValueError(f'lost_steps must list [episode, step] pairs, got {lost!r}')
    low, high = reading_range(manifest, channels)
    if not low < high:
        raise ValueError(f'reading_range must be [low, high] with low < high, got {[low, high]}')


def reading_range(manifest: Mapping[str, Any], channels: int) -> tuple[float, float]:
    """Allowed readings: the manifest's ``reading_range``, else 0..525 on a Khepera."""
    if 'reading_range' in manifest:
        value = manifest['reading_range']
        if not isinstance(value, list) or len(value) != 2 or not all(map(_is_number, value)):
            raise ValueError(f'reading_range must be [low, high], got {value!r}')
        return float(value[0]), float(value[1])
    return KHEPERA_RANGE if channels == KHEPERA_CHANNELS else (-math.inf, math.inf)


def _is_number(value: object) -> TypeGuard[float]:
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)


def finish_manifest(rec: Recording) -> dict[str, Any]:
    """The manifest to write: the given keys plus channels, samples and lost steps.

    Lost steps are the gaps in the data plus any the recorder declared (steps lost
    after an episode's last sample leave no gap).
    """
    manifest = dict(rec.manifest)
    if rec.channels != KHEPERA_CHANNELS:
        manifest['channels'] = rec.channels
    manifest['samples'] = len(rec)
    lost, duplicated = rec.step_problems()
    if duplicated:
        raise RecordingError(f'steps recorded twice: {_pairs(duplicated)}')
    declared = {tuple(p) for p in manifest.get('lost_steps', [])}
    manifest['lost_steps'] = [list(p) for p in sorted(declared | set(lost))]
    return manifest


def _pairs(pairs: list[tuple[int, int]], limit: int = 5) -> str:
    text = ', '.join(f'(episode {e}, step {s})' for e, s in pairs[:limit])
    return text + (f' and {len(pairs) - limit} more' if len(pairs) > limit else '')


def dump_manifest(manifest: Mapping[str, Any]) -> str:
    return yaml.safe_dump(_plain(manifest), sort_keys=False, default_flow_style=None)


def _plain(value: object) -> object:
    """numpy scalars and tuples to YAML-safe Python values."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


# -- rows -------------------------------------------------------------------------------

def first_bad_row(rec: Recording) -> tuple[int, str] | None:
    """(index, problem) of the first sample that breaks the format, or None."""
    manifest, n = rec.manifest, len(rec)
    low, high = reading_range(manifest, rec.channels)
    used = rec.readings[:, rec.channels_used]
    known = ~np.isnan(rec.direction)
    # (the mask of bad rows, the problem in row i)
    checks: tuple[tuple[np.bool_ | NDArray[np.bool_], Callable[[int], str]], ...] = (
        ((rec.episode < 0) | (rec.step < 0),
         lambda i: f'episode and step must be >= 0, got {rec.episode[i]}, {rec.step[i]}'),
        (~np.isin(rec.condition, list(manifest['conditions'])),
         lambda i: f'condition {str(rec.condition[i])!r} is not in the manifest conditions '
                   f'{sorted(manifest["conditions"])}'),
        (np.isinf(rec.heading_deg), lambda i: 'heading_deg must be finite or empty'),
        (~((used >= low) & (used <= high)).all(axis=1),       # NaN fails too
         lambda i: _bad_reading(rec, i, low, high)),
        (known != ~np.isnan(rec.power),
         lambda i: 'direction and power must both be given or both be empty'),
        (known & (~np.isin(rec.direction, (-1, 1)) | ~np.isin(rec.power, np.arange(10))),
         lambda i: f'direction must be -1 or +1 and power 0..9, got {rec.direction[i]:g}, '
                   f'{rec.power[i]:g}'),
    )
    bad = [(int(np.argmax(mask)), message) for mask, message in checks if n and mask.any()]
    if not bad:
        return None
    i, message = min(bad, key=lambda b: b[0])
    return i, message(i)


def _bad_reading(rec: Recording, i: int, low: float, high: float) -> str:
    for c in rec.channels_used:
        value = rec.readings[i, c]
        if math.isnan(value):
            return f's{c} is empty but channels_used includes it'
        if not low <= value <= high:
            return f's{c} must be a reading in [{low:g}, {high:g}], got {value:g}'
    return 'bad reading'


def check_sequence(rec: Recording, where: Callable[[int], str], name: str,
                   manifest_name: str) -> None:
    """Every (episode, step) once, in order within its episode, as the manifest declares.

    ``where(i)`` names sample i (a line or a message) in errors.
    """
    last: dict[int, int] = {}
    first: dict[tuple[int, int], int] = {}
    for i, (e, s) in enumerate(zip(rec.episode.tolist(), rec.step.tolist())):
        if (e, s) in first:
            raise RecordingError(f'{where(i)}: duplicate sample (episode {e}, step {s}), '
                                 f'first at {where(first[e, s])}')
        if s < last.get(e, -1):
            raise RecordingError(f'{where(i)}: step {s} of episode {e} comes after step '
                                 f'{last[e]}')
        first[e, s] = i
        last[e] = s
    samples = rec.manifest.get('samples')
    if samples is not None and samples != len(rec):
        raise RecordingError(f'{name}: {manifest_name} says {samples} samples, found '
                             f'{len(rec)} (truncated or extended?)')
    if 'lost_steps' in rec.manifest:
        declared = {tuple(p) for p in rec.manifest['lost_steps']}
        missing = [p for p in rec.step_problems()[0] if p not in declared]
        if missing:
            raise RecordingError(f'{name}: steps missing that {manifest_name} does not list '
                                 f'as lost: {_pairs(missing)}')
