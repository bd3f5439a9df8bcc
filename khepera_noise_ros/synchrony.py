"""Sensor synchrony, the paper's section 2: how strongly the noise of sensor pairs is correlated.

Per condition, each pair's Pearson correlation is taken over the *fluctuations*:
every episode (one fixed heading in a stationary recording) is centred on its
own means first, so that readings at different headings do not masquerade as
correlated noise.  Light readings drift and flicker, so successive samples are
not independent; the moving-block bootstrap resamples blocks of consecutive
samples within episodes and gives an interval that respects that.  The Fisher-z
interval, which assumes independent samples, is reported beside it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import norm

from .gap import bootstrap as blocklength
from .recording import Recording

# Section 2: two light sensors one inch apart, read every second for a minute.
PAPER_CORRELATION = {'bulb_1ft': 0.05, 'bulb_2ft': 0.85, 'room_fluorescent': 0.76,
                     'room_dark': 0.98}
PAPER_PAIR = (2, 3)            # the Khepera's two adjacent sensors that face the lamp
PAPER_FIGURES = {'bulb': ('bulb_1ft', 'bulb_2ft'),
                 'ambient': ('room_fluorescent', 'room_dark')}
PAPER_TITLES = {'bulb': 'Lamp at 1 ft and 2 ft (cf. the paper\'s Figure 2)',
                'ambient': 'Room light, fluorescent on and off (cf. the paper\'s Figure 3)'}
CHUNK = 256                    # bootstrap replicates per vectorised batch (memory bound)


@dataclass(frozen=True)
class SensorStats:
    """Level and spread of one sensor; ``std`` is of the fluctuations about each episode's mean."""

    mean: float
    std: float
    min: float
    max: float

    @property
    def range(self) -> float:
        return self.max - self.min


@dataclass(frozen=True)
class PairCorrelation:
    sensors: tuple[int, int]
    r: float
    fisher_ci: tuple[float, float]
    bootstrap_ci: tuple[float, float]


@dataclass
class ConditionSynchrony:
    """Everything section 2 reports about one condition."""

    condition: str
    samples: int
    episodes: int
    channels: list[int]                 # the used channels, order of ``matrix``
    block_length: int
    sensors: dict[int, SensorStats]
    matrix: np.ndarray                  # (len(channels),) * 2 correlations
    pairs: list[PairCorrelation] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {'condition': self.condition, 'samples': self.samples,
                'episodes': self.episodes, 'block_length': self.block_length,
                'channels': self.channels,
                'sensors': {f's{c}': {'mean': s.mean, 'std': s.std, 'min': s.min,
                                      'max': s.max, 'range': s.range}
                            for c, s in self.sensors.items()},
                'pairs': [{'sensors': list(p.sensors), 'r': _finite(p.r),
                           'fisher_ci': [_finite(v) for v in p.fisher_ci],
                           'bootstrap_ci': [_finite(v) for v in p.bootstrap_ci],
                           'paper_r': paper_r(self.condition, p.sensors)}
                          for p in self.pairs],
                'matrix': [[_finite(v) for v in row] for row in self.matrix]}


def paper_r(condition: str, pair: tuple[int, int]) -> float | None:
    """Section 2's correlation for this condition, for the pair that stands for its sensors."""
    return PAPER_CORRELATION.get(condition) if tuple(pair) == PAPER_PAIR else None


def _finite(value: float) -> float | None:
    """JSON has no NaN: an undefined correlation (a constant sensor) is null."""
    return None if math.isnan(value) else float(value)


# -- statistics ---------------------------------------------------------------------------

def centred(x: np.ndarray, segments: list[slice]) -> np.ndarray:
    """x (N, C) with each segment's column means removed."""
    out = np.empty_like(x, dtype=np.float64)
    for s in segments:
        out[s] = x[s] - x[s].mean(axis=0)
    return out


def correlation(x: np.ndarray) -> np.ndarray:
    """(..., C, C) Pearson correlations of already centred x (..., N, C); NaN if constant."""
    cov = np.einsum('...nc,...nd->...cd', x, x)
    scale = np.sqrt(np.einsum('...cc->...c', cov))
    with np.errstate(invalid='ignore', divide='ignore'):
        r = cov / (scale[..., :, None] * scale[..., None, :])
    return np.clip(r, -1.0, 1.0)


def fisher_interval(r: float, samples: int, episodes: int = 1,
                    confidence: float = 0.95) -> tuple[float, float]:
    """Fisher-z interval for independent samples; centring each episode costs a degree."""
    n_eff = samples - (episodes - 1)
    if math.isnan(r) or n_eff <= 3:
        return math.nan, math.nan
    z, half = math.atanh(min(max(r, -0.999999), 0.999999)), \
        norm.ppf(0.5 + confidence / 2) / math.sqrt(n_eff - 3)
    return math.tanh(z - half), math.tanh(z + half)


def block_length(x: np.ndarray, segments: list[slice]) -> int:
    """Block length for the moving-block bootstrap: the project's one rule
    (``gap.blocklength``, Politis and White 2004 with Patton et al. 2009), the longest
    any used sensor needs, at least 1, at most a third of the shortest episode."""
    return blocklength.block_length(x, segments)


def bootstrap_correlations(x: np.ndarray, segments: list[slice], length: int,
                           resamples: int, rng: np.random.Generator) -> np.ndarray:
    """(resamples, C, C) correlations of moving-block resamples of raw x (N, C).

    Blocks never cross an episode boundary, and each resampled episode is
    re-centred, as the point estimate is.
    """
    out = np.empty((resamples, x.shape[1], x.shape[1]))
    for start in range(0, resamples, CHUNK):
        count = min(CHUNK, resamples - start)
        index = np.concatenate([_block_index(s, length, count, rng) for s in segments], axis=1)
        sample = x[index]                                        # (count, N, C)
        offset = 0
        for s in segments:
            n = s.stop - s.start
            part = sample[:, offset:offset + n]
            part -= part.mean(axis=1, keepdims=True)
            offset += n
        out[start:start + count] = correlation(sample)
    return out


def _block_index(segment: slice, length: int, count: int, rng) -> np.ndarray:
    n = segment.stop - segment.start
    length = min(length, n)
    blocks = -(-n // length)
    starts = rng.integers(0, n - length + 1, size=(count, blocks, 1))
    return (segment.start + starts + np.arange(length)).reshape(count, -1)[:, :n]


# -- the analysis -------------------------------------------------------------------------

def episode_segments(rec: Recording) -> list[slice]:
    """Runs of consecutive rows from one episode (the recording must keep episodes together)."""
    change = np.nonzero(np.diff(rec.episode))[0] + 1
    bounds = np.concatenate([[0], change, [len(rec)]])
    return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def default_pairs(channels: list[int]) -> list[tuple[int, int]]:
    """The paper's pair: two adjacent sensors facing the light (s2, s3 on a Khepera)."""
    if {2, 3} <= set(channels):
        return [(2, 3)]
    return [tuple(channels[:2])] if len(channels) >= 2 else []


def analyse(rec: Recording, pairs=None, confidence: float = 0.95, resamples: int = 2000,
            block: int | None = None, seed: int = 0,
            by_heading: bool = False) -> list[ConditionSynchrony]:
    """Section 2's numbers per condition (or per condition and heading)."""
    if not 0 < confidence < 1:
        raise ValueError(f'confidence must be in (0, 1), got {confidence}')
    if resamples < 1:
        raise ValueError(f'resamples must be >= 1, got {resamples}')
    channels = rec.channels_used
    pairs = default_pairs(channels) if pairs is None else [tuple(p) for p in pairs]
    for p in pairs:
        if len(p) != 2 or p[0] == p[1] or not set(p) <= set(channels):
            raise ValueError(f'a pair names two different used channels {channels}, got '
                             f'{list(p)}')
    rng = np.random.default_rng(seed)
    return [_analyse_group(label, rec.select(mask), channels, pairs, confidence, resamples,
                           block, rng) for label, mask in groups(rec, by_heading)]


def groups(rec: Recording, by_heading: bool = False) -> list[tuple[str, np.ndarray]]:
    """(label, row mask) per condition, or per condition and start heading."""
    out = []
    for condition in rec.conditions():
        mask = rec.condition == condition
        if not by_heading:
            out.append((condition, mask))
            continue
        for heading in _start_headings(rec, mask):
            label = f'{condition} @ {heading:g} deg'
            episodes = [e for e in np.unique(rec.episode[mask])
                        if _start_heading(rec, mask & (rec.episode == e)) == heading]
            out.append((label, mask & np.isin(rec.episode, episodes)))
    return out


def _start_heading(rec: Recording, mask: np.ndarray) -> float:
    return float(rec.heading_deg[np.argmax(mask)])


def _start_headings(rec: Recording, mask: np.ndarray) -> list[float]:
    seen = []
    for e in dict.fromkeys(rec.episode[mask].tolist()):
        h = _start_heading(rec, mask & (rec.episode == e))
        if h not in seen and not (math.isnan(h) and any(map(math.isnan, seen))):
            seen.append(h)
    return seen


def _analyse_group(label: str, rec: Recording, channels: list[int], pairs, confidence: float,
                   resamples: int, block: int | None, rng) -> ConditionSynchrony:
    x = rec.readings[:, channels].astype(np.float64)
    segments = episode_segments(rec)
    fluctuations = centred(x, segments)
    matrix = correlation(fluctuations)
    length = block or block_length(fluctuations, segments)
    boot = bootstrap_correlations(x, segments, length, resamples, rng)
    tail = 100 * (1 - confidence) / 2
    col = {c: i for i, c in enumerate(channels)}
    dof = len(rec) - len(segments)
    spread = np.sqrt((fluctuations ** 2).sum(axis=0) / dof) if dof > 0 \
        else np.full(len(channels), math.nan)
    result = ConditionSynchrony(
        condition=label, samples=len(rec), episodes=len(segments), channels=channels,
        block_length=length, matrix=matrix,
        sensors={c: SensorStats(float(x[:, i].mean()), float(spread[i]), float(x[:, i].min()),
                                float(x[:, i].max())) for c, i in col.items()})
    for a, b in pairs:
        r = float(matrix[col[a], col[b]])
        draws = boot[:, col[a], col[b]]
        draws = draws[~np.isnan(draws)]
        interval = tuple(float(v) for v in np.percentile(draws, [tail, 100 - tail])) \
            if draws.size else (math.nan, math.nan)
        result.pairs.append(PairCorrelation(
            (a, b), r, fisher_interval(r, len(rec), len(segments), confidence), interval))
    return result


# -- figures ------------------------------------------------------------------------------

def _pyplot():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def plot_pair(rec: Recording, pair: tuple[int, int], conditions: list[str], path,
              title: str | None = None) -> None:
    """Two sensors' time series per condition, like the paper's Figures 2-5.

    Each condition shows its first episode; the legend gives that episode's
    correlation (the table pools all of a condition's episodes).
    """
    plt = _pyplot()
    a, b = pair
    fig, ax = plt.subplots(figsize=(7, 4))
    period = rec.manifest.get('sample_period_s', 1.0)
    for colour, condition in zip(plt.rcParams['axes.prop_cycle'].by_key()['color'] * 4,
                                 conditions):
        mask = rec.condition == condition
        if not mask.any():
            raise ValueError(f'condition {condition!r} is not in the recording; it has '
                             f'{rec.conditions()}')
        episode = rec.select(mask & (rec.episode == rec.episode[np.argmax(mask)]))
        t = episode.step * period
        r = correlation(centred(episode.readings[:, [a, b]], [slice(0, len(episode))]))[0, 1]
        where = '' if math.isnan(episode.heading_deg[0]) \
            else f', heading {episode.heading_deg[0]:g} deg'
        ax.plot(t, episode.readings[:, a], color=colour, lw=1.2,
                label=f'{condition} s{a}')
        ax.plot(t, episode.readings[:, b], color=colour, lw=1.2, ls='--',
                label=f'{condition} s{b}  (r = {r:.2f}{where})')
    ax.set_xlabel('time (s)')
    ax.set_ylabel('light reading (0 = brightest)')
    ax.set_title(title or f'Sensors s{a} and s{b}')
    ax.legend(fontsize=8, loc='best')
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_matrix(result: ConditionSynchrony, path) -> None:
    """Heat map of the condition's correlation matrix over the used channels."""
    plt = _pyplot()
    k = len(result.channels)
    fig, ax = plt.subplots(figsize=(1.0 + 0.55 * k, 0.6 + 0.5 * k))
    image = ax.imshow(result.matrix, vmin=-1, vmax=1, cmap='RdBu_r')
    labels = [f's{c}' for c in result.channels]
    ax.set_xticks(range(k), labels)
    ax.set_yticks(range(k), labels)
    for i in range(k):
        for j in range(k):
            value = result.matrix[i, j]
            ax.text(j, i, '' if math.isnan(value) else f'{value:.2f}', ha='center',
                    va='center', fontsize=7, color='white' if abs(value) > 0.6 else 'black')
    ax.set_title(f'{result.condition}: noise correlation', fontsize=9)
    fig.colorbar(image, ax=ax, fraction=0.046, pad=0.04)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
