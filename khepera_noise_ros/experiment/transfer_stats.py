"""The transfer experiment's numbers: each arm's real fitness with its interval, the share
of the distance to the robot-trained controllers recovered, and verdicts from intervals.

A verdict compares an arm with the stock simulator's controllers by the Welch 95%
interval of the difference of their mean real fitness: ``better`` when it lies above 0,
``worse`` when below, else ``no detectable difference``, said with the smallest
difference the design finds with 80% power at the measured spreads.  The share recovered
is (diagnosed - stock) / (robot-trained - stock), defined where the robot-trained
controllers are clearly better (their interval over stock above 0); its interval is a
percentile bootstrap over trials (stock and robot-trained resampled together, as the
robot-trained runs start from the stock bests), unbounded when the resampled distance
reaches 0.  Do no harm: the diagnosed simulator is recommended only if its controllers'
mean real fitness is not below the stock one's.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import stats as sps

from .power import TARGET_POWER, minimum_detectable_difference
from .stats import CONFIDENCE, summarize
from .transfer import DIAGNOSED, ROBOT, STOCK, Outcome

VERDICTS = ('better', 'no detectable difference', 'worse')
BOOTSTRAP = 4000
TEST = "Welch's t-test, two-sided"


def interval(values) -> dict:
    """Mean, SD and 95% t interval of per-trial values."""
    s = summarize(values)
    return {'mean': s.mean, 'sd': s.sd, 'ci_low': s.ci_low, 'ci_high': s.ci_high, 'n': s.n}


def versus(a: np.ndarray, b: np.ndarray, names: tuple[str, str] = ('arm', STOCK)) -> dict:
    """a - b: Welch's 95% interval and p, the verdict, and the smallest difference the
    design detects with 80% power (the power of a 'no detectable difference')."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    va, vb = a.var(ddof=1) / a.size, b.var(ddof=1) / b.size
    d = float(a.mean() - b.mean())
    if va + vb == 0:
        low = high = d
        t = p = math.nan
    else:
        df = (va + vb) ** 2 / (va * va / (a.size - 1) + vb * vb / (b.size - 1))
        half = float(sps.t.ppf(0.5 + CONFIDENCE / 2, df)) * math.sqrt(va + vb)
        low, high = d - half, d + half
        result = sps.ttest_ind(a, b, equal_var=False)
        t, p = float(result.statistic), float(result.pvalue)
    sd_a, sd_b = float(a.std(ddof=1)), float(b.std(ddof=1))
    mdd = minimum_detectable_difference(sd_a, a.size, sd_b=sd_b, n_b=b.size) \
        if sd_a > 0 and sd_b > 0 else 0.0
    kind = 'better' if low > 0 else ('worse' if high < 0 else 'no detectable difference')
    what = f'{d:+.3f} [{low:+.3f}, {high:+.3f}]'
    if kind == 'no detectable difference':
        text = (f'no detectable difference from {names[1]}: {what}; with {a.size} and '
                f'{b.size} trials a difference of {mdd:.3f} would be found with '
                f'{TARGET_POWER:.0%} power')
    else:
        text = f'{kind} than {names[1]}: {what}' + (f' (p = {p:.2g})' if np.isfinite(p) else '')
    return {'difference': d, 'ci_low': low, 'ci_high': high, 't': _finite(t),
            'p': _finite(p), 'mdd': mdd, 'verdict': kind, 'text': text}


def share(stock: np.ndarray, diagnosed: np.ndarray, robot: np.ndarray,
          replicates: int = BOOTSTRAP, seed: int = 0) -> dict:
    """(diagnosed - stock) / (robot - stock), with its percentile bootstrap interval."""
    stock, diagnosed, robot = (np.asarray(x, float) for x in (stock, diagnosed, robot))
    gain = float(robot.mean() - stock.mean())
    point = float(diagnosed.mean() - stock.mean()) / gain if gain > 0 else math.nan
    rng = np.random.default_rng(seed)
    paired = rng.integers(0, stock.size, (replicates, stock.size))
    own = rng.integers(0, diagnosed.size, (replicates, diagnosed.size))
    s, r = stock[paired].mean(axis=1), robot[paired].mean(axis=1)
    distance = r - s
    alpha = 1 - CONFIDENCE
    if np.mean(distance <= 0) > alpha / 2 or not np.isfinite(point):
        return {'share': _finite(point), 'ci_low': None, 'ci_high': None,
                'note': 'unbounded: the resampled distance to the robot-trained '
                        'controllers reaches 0'}
    ratio = (diagnosed[own].mean(axis=1) - s) / np.where(distance > 0, distance, np.nan)
    low, high = np.nanquantile(ratio, [alpha / 2, 1 - alpha / 2])
    return {'share': point, 'ci_low': float(low), 'ci_high': float(high),
            'note': f'percentile bootstrap, {replicates} replicates'}


def block(outcome: Outcome) -> dict:
    """The ``transfer`` block of diagnosis.json (before = stock, after = diagnosed)."""
    o = outcome
    arms = {}
    for name in o.arms:
        if name not in o.real:
            arms[name] = {'tested': False, 'same_as': o.same_as.get(name)}
            continue
        real, sim = o.real[name], o.sim.get(name)
        entry = {'tested': True, 'same_as': o.same_as.get(name), 'real': interval(real),
                 'sim': None if sim is None else interval(sim),
                 'gap': None if sim is None else interval(sim - real),
                 'values': {'real': real.tolist(),
                            'sim': None if sim is None else sim.tolist()}}
        if name != STOCK and o.same_as.get(name) != STOCK and STOCK in o.real:
            entry['versus_stock'] = versus(real, o.real[STOCK], (name, STOCK))
        arms[name] = entry
    out = {'protocol': 'measured', 'trials': o.trials, 'test_episodes': o.test_episodes,
           'ea': dataclasses.asdict(o.ea), 'seed': o.seed, 'test': TEST,
           'status': 'complete' if o.complete else 'stopped', 'error': o.error,
           'stopped_at': None if o.complete else o.stage, 'done': o.done(), 'arms': arms}
    out.update(_before_after(o))
    out.update(_ceiling(o, arms))
    out.update(recommendation(arms))
    return out


def _before_after(o: Outcome) -> dict:
    """The keys the block always had: before = stock, after = diagnosed."""
    keys = {}
    for when, name in (('before', STOCK), ('after', DIAGNOSED)):
        real, sim = o.real.get(name), o.sim.get(name)
        keys[f'real_fitness_{when}'] = None if real is None else float(real.mean())
        keys[f'sim_fitness_{when}'] = None if sim is None else float(sim.mean())
        keys[f'fitness_gap_{when}'] = None if real is None or sim is None \
            else float((sim - real).mean())
    keys.update(gap_t=None, gap_p=None, real_t=None, real_p=None)
    if all(n in o.real and n in o.sim for n in (STOCK, DIAGNOSED)):
        gap = _welch(o.sim[STOCK] - o.real[STOCK], o.sim[DIAGNOSED] - o.real[DIAGNOSED])
        real = _welch(o.real[DIAGNOSED], o.real[STOCK])
        keys.update(gap_t=gap[0], gap_p=gap[1], real_t=real[0], real_p=real[1])
    return keys


def _ceiling(o: Outcome, arms: dict) -> dict:
    keys: dict = {'real_fitness_robot_trained': None, 'ceiling_gain': None,
                  'ceiling_clear': None, 'share_recovered': None,
                  'share_recovered_interval': None, 'share_note': None}
    if ROBOT not in o.real or STOCK not in o.real:
        return keys
    gain = arms[ROBOT]['versus_stock']
    keys.update(real_fitness_robot_trained=float(o.real[ROBOT].mean()), ceiling_gain=gain,
                ceiling_clear=gain['verdict'] == 'better')
    if not keys['ceiling_clear']:
        keys['share_note'] = ('the robot-trained controllers are not clearly better than the '
                              "stock simulator's: there is no distance to recover")
    elif DIAGNOSED in o.real:
        s = share(o.real[STOCK], o.real[DIAGNOSED], o.real[ROBOT], seed=o.seed)
        keys.update(share_recovered=s['share'], share_note=s['note'],
                    share_recovered_interval=None if s['ci_low'] is None
                    else [s['ci_low'], s['ci_high']])
    return keys


def recommendation(arms: dict) -> dict:
    """Do no harm: recommend the diagnosed simulator only when its controllers' mean real
    fitness is not below the stock simulator's (and so never when it is worse)."""
    d = arms.get(DIAGNOSED, {})
    if not d.get('tested') or 'versus_stock' not in d:
        return {'verdict': None, 'verdict_text': None, 'recommended': None,
                'recommendation': 'not tested on the robot: the diagnosed simulator was not '
                                  'compared with the stock one'}
    v = d['versus_stock']
    ok = v['verdict'] != 'worse' and v['difference'] >= 0
    if ok:
        verb = 'did' if v['verdict'] == 'better' else 'showed'
        reason = f"on the robot its controllers {verb} {v['text']}"
    elif v['verdict'] == 'worse':
        reason = f"its controllers score on the robot worse than the stock simulator's: " \
                 f"{v['difference']:+.3f} [{v['ci_low']:+.3f}, {v['ci_high']:+.3f}]"
    else:
        reason = (f"its controllers' mean real fitness is below the stock simulator's "
                  f"({v['difference']:+.3f} [{v['ci_low']:+.3f}, {v['ci_high']:+.3f}]; not "
                  f"significant, but no sign of a gain)")
    return {'verdict': v['verdict'], 'verdict_text': v['text'], 'recommended': ok,
            'recommendation': reason}


def _welch(a: np.ndarray, b: np.ndarray) -> tuple[float | None, float | None]:
    if np.ptp(a) == 0 and np.ptp(b) == 0:
        return None, None
    r = sps.ttest_ind(a, b, equal_var=False)
    return _finite(r.statistic), _finite(r.pvalue)


def _finite(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None
