"""Expectile Regression baseline of benchmarks/extremum_vs_expectile.py (paper Sec. III-B, Fig. 3): the
asymmetric L2 loss, its minimiser (the tau-expectile), the benchmark distributions' exact bounds, and a
tiny end-to-end run of the benchmark."""

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "extremum_vs_expectile.py"


def _load():
    # ``benchmarks`` is not a package; load the file (registered first, as dataclasses look the module up).
    name = "extremum_vs_expectile"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, _PATH)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


evx = _load()


def _exact_expectile(x: np.ndarray, tau: float) -> float:
    """Solve tau * sum (x - m)+ = (1 - tau) * sum (m - x)+ exactly: it is linear in m between sorted samples."""
    x = np.sort(np.asarray(x, dtype=np.float64))
    for k in range(1, len(x)):  # m in [x[k-1], x[k]]: the first k samples are below m
        below, above = x[:k], x[k:]
        # tau * (sum(above) - m * len(above)) = (1 - tau) * (m * k - sum(below))
        m = (tau * above.sum() + (1 - tau) * below.sum()) / (tau * len(above) + (1 - tau) * k)
        if x[k - 1] - 1e-12 <= m <= x[k] + 1e-12:
            return float(m)
    raise AssertionError("no root")


def test_expectile_loss_matches_the_formula_on_hand_values():
    """|tau - 1(u<0)| u^2: weight 1 - tau below zero, tau above (and 0 at u = 0), element-wise."""
    u = torch.tensor([-2.0, -0.5, 0.0, 1.0, 3.0])
    assert torch.allclose(evx.expectile_loss(u, 0.1), torch.tensor([3.6, 0.225, 0.0, 0.1, 0.9]))
    assert torch.allclose(evx.expectile_loss(u, 0.99), torch.tensor([0.04, 0.0025, 0.0, 0.99, 8.91]))
    assert torch.allclose(evx.expectile_loss(u, 0.5), 0.5 * u**2)
    # Per-column taus broadcast (the two-head network uses taus of shape (2,)).
    both = evx.expectile_loss(u[:, None].expand(-1, 2), torch.tensor([0.1, 0.99]))
    assert torch.allclose(both, torch.stack([evx.expectile_loss(u, 0.1), evx.expectile_loss(u, 0.99)], 1))


@pytest.mark.parametrize("tau", [0.01, 0.2, 0.5, 0.99])
def test_loss_minimiser_over_constants_is_the_expectile(tau):
    """argmin_m mean L(x - m) is the tau-expectile: hand values on [0, 1, 2, 10], solver agreement on a random array."""
    hand = {0.01: 0.13 / 1.02, 0.5: 3.25, 0.99: 9.93 / 1.02}  # e.g. tau=0.99: 0.99(10-m) = 0.01(3m-3)
    small = np.array([0.0, 1.0, 2.0, 10.0])
    if tau in hand:
        assert _exact_expectile(small, tau) == pytest.approx(hand[tau], abs=1e-12)
    rng = np.random.default_rng(0)
    for x in (small, np.concatenate([rng.normal(0, 1, 40), rng.normal(5, 0.1, 3)])):
        m = torch.zeros((), dtype=torch.float64, requires_grad=True)
        opt = torch.optim.LBFGS([m], lr=1, max_iter=200, tolerance_grad=1e-14, line_search_fn="strong_wolfe")
        xt = torch.as_tensor(x)

        def closure(opt=opt, xt=xt, m=m):
            opt.zero_grad()
            loss = evx.expectile_loss(xt - m, tau).mean()
            loss.backward()
            return loss

        opt.step(closure)
        exact = _exact_expectile(x, tau)
        assert m.item() == pytest.approx(exact, abs=1e-6)
        assert float(evx.sample_expectile(x, tau)) == pytest.approx(exact, abs=1e-9)
    # Extreme taus approach the sample min / max, but stay inside (the conservativeness of Fig. 3).
    assert small.min() < _exact_expectile(small, 0.01) < _exact_expectile(small, 0.99) < small.max()


def test_distributions_true_bounds_contain_and_touch_their_samples():
    """Every sample lies in [lo(c), hi(c)], and the samples reach both ends (the bounds are tight)."""
    assert len(evx.DISTRIBUTIONS) >= 3
    gen = torch.Generator().manual_seed(0)
    for name, dist in evx.DISTRIBUTIONS.items():
        c, x = dist.sample(20_000, gen)
        assert c.shape == (20_000, 1) and x.shape == (20_000,) and 0 <= c.min() and c.max() <= 1
        lo, hi = dist.bounds(c[:, 0])
        assert (lo <= x + 1e-6).all() and (x <= hi + 1e-6).all(), name
        assert (x - lo).min() < 0.002 and (hi - x).min() < 0.002, name
        assert (hi - lo).min() > 0.1, name  # genuinely spread (multi-modal) at every c
    far = evx.DISTRIBUTIONS["skewed_plus_far_5pct"]
    c, x = far.sample(20_000, gen)
    assert abs((x > 0.72).float().mean().item() - 0.05) < 0.01  # the far mode carries ~5% of the mass


def test_short_benchmark_run_returns_finite_errors_and_a_table(tmp_path):
    """A few training steps on tiny networks: every error is finite, and the report, table and plot are written."""
    torch.set_num_threads(1)
    bench = evx.run_benchmark(
        steps=5, seeds=2, grid_size=11, hidden_dims=(16, 16), batch_size=32, euler_steps=3
    )
    assert set(bench["results"]) == set(evx.DISTRIBUTIONS) and bench["grid"].shape == (11,)
    for e in bench["results"].values():
        for key in ("mae", "gap"):
            for m in evx.METHODS:
                for b in evx.BOUNDS:
                    assert len(e[key][m][b]) == 2 and all(math.isfinite(v) for v in e[key][m][b])
        assert all(v >= 0 for m in evx.METHODS for b in evx.BOUNDS for v in e["mae"][m][b])
        assert all(e["curves"][m][b].shape == (11,) for m in evx.METHODS for b in evx.BOUNDS)
        assert np.isfinite(e["pop_expectile"]).all() and e["pop_expectile"].shape == (2, 11)
    lines = evx.format_table(bench).splitlines()
    assert len(lines) == 2 + len(evx.DISTRIBUTIONS)
    assert (
        all(line.count("|") == 6 for line in lines)
        and "flow min MAE" in lines[0]
        and "expectile(0.99)" in lines[0]
    )
    assert [line.split("|")[1].strip() for line in lines[2:]] == list(evx.DISTRIBUTIONS)
    assert all(line.count("±") == 4 for line in lines[2:])

    evx.plot(bench, tmp_path / "p.png", n_points=200)
    assert (tmp_path / "p.png").stat().st_size > 0
