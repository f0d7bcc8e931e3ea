"""Flow-matching core (paper eq. 1-2): unit-ball source, linear path, loss, Euler integration, and the
extremum property of a 1-D critic flow (paper Fig. 3)."""

import math

import pytest
import torch

from lerobot_efm.agents import Critic
from lerobot_efm.flow import (
    euler_integrate,
    flow_matching_loss,
    heun_integrate,
    integrate,
    interpolate,
    sample_source,
    sample_unit_ball,
)


@pytest.mark.parametrize("n", [1, 2, 3])
def test_unit_ball_is_uniform_in_the_ball(n):
    """Samples lie in the unit ball, radii follow r^(1/n) and directions are isotropic."""
    x = sample_unit_ball((20_000, n), event_dims=1)
    norms = x.norm(dim=-1)
    assert x.shape == (20_000, n) and norms.max() <= 1 + 1e-6
    assert abs((norms < 0.5).float().mean().item() - 0.5**n) < 0.012  # P(r < 1/2) = (1/2)^n
    assert abs((norms < 0.9).float().mean().item() - 0.9**n) < 0.012
    assert x.mean(0).abs().max() < 0.02
    assert torch.allclose((x**2).mean(0), torch.full((n,), 1 / (n + 2)), atol=0.012)  # E[x_i^2] = 1/(n+2)


def test_unit_ball_flattens_the_event_dims():
    """With event_dims=2 a (B, L, C) draw is one point of the ball of R^(L*C), not L points of R^C."""
    x = sample_unit_ball((20_000, 4, 2), event_dims=2)
    flat = x.flatten(1).norm(dim=-1)
    assert x.shape == (20_000, 4, 2) and flat.max() <= 1 + 1e-6
    assert flat.max() > 0.99 and abs((flat < 0.8).float().mean().item() - 0.8**8) < 0.012
    per_row = sample_unit_ball((8_000, 4, 2), event_dims=1)
    assert per_row.norm(dim=-1).max() <= 1 + 1e-6 and per_row.flatten(1).norm(dim=-1).max() > 1.2


def test_unit_ball_generator_is_reproducible():
    """The same generator seed gives the same draw, a different seed a different one."""
    draw = [sample_unit_ball((5, 3), 1, generator=torch.Generator().manual_seed(s)) for s in (1, 1, 2)]
    assert torch.equal(draw[0], draw[1]) and not torch.equal(draw[0], draw[2])


def test_sample_source_kinds():
    """ "gaussian" is a standard normal (unbounded), "unit_ball" is bounded, unknown kinds are named."""
    g = sample_source("gaussian", (4_000, 8, 2), 2)
    assert g.shape == (4_000, 8, 2) and abs(g.std().item() - 1) < 0.03 and g.flatten(1).norm(dim=-1).min() > 1
    assert sample_source("unit_ball", (100, 8, 2), 2).flatten(1).norm(dim=-1).max() <= 1 + 1e-6
    with pytest.raises(ValueError, match="'laplace'"):
        sample_source("laplace", (2, 3), 1)


def test_interpolate_endpoints_broadcasting_and_velocity():
    """x_t is x_src at t=0 and x_dst at t=1, t is per sample, the velocity is x_dst - x_src."""
    src, dst = torch.randn(3, 8, 2), torch.randn(3, 8, 2)
    x_t, v = interpolate(src, dst, torch.tensor([0.0, 1.0, 0.25]))
    assert torch.equal(x_t[0], src[0]) and torch.allclose(x_t[1], dst[1])
    assert torch.allclose(x_t[2], 0.75 * src[2] + 0.25 * dst[2])
    assert torch.equal(v, dst - src)
    x_half, _ = interpolate(src, dst, torch.tensor(0.5))
    assert torch.allclose(x_half, (src + dst) / 2)


def test_euler_is_exact_for_a_constant_velocity():
    """A constant field moves x0 by exactly v over [0, 1], whatever the number of steps."""
    x0, v = torch.randn(4, 3), torch.randn(4, 3)
    for steps in (1, 7):
        assert torch.allclose(euler_integrate(lambda x, t: v, x0, steps), x0 + v, atol=1e-6)


def test_euler_converges_to_the_exponential():
    """dx/dt = x from 1 gives (1 + 1/N)^N, within the first-order Euler error e/(2N) of e."""
    x0 = torch.ones(2, dtype=torch.float64)
    errors = []
    for steps in (20, 40):
        x = euler_integrate(lambda x, t: x, x0, steps)
        assert torch.allclose(x, torch.full_like(x, (1 + 1 / steps) ** steps))
        errors.append(math.e - x[0].item())
        assert 0 < errors[-1] < math.e / steps
    assert 1.8 < errors[0] / errors[1] < 2.2  # first order


def test_euler_passes_uniform_scalar_times_and_rejects_zero_steps():
    """t is k/N as a 0-d tensor of x's dtype for k = 0..N-1; num_steps < 1 raises."""
    seen = []
    euler_integrate(
        lambda x, t: seen.append(t) or torch.zeros_like(x), torch.zeros(3, dtype=torch.float64), 4
    )
    assert [t.dim() for t in seen] == [0] * 4 and {t.dtype for t in seen} == {torch.float64}
    assert [t.item() for t in seen] == [0.0, 0.25, 0.5, 0.75]
    with pytest.raises(ValueError, match="num_inference_steps"):
        euler_integrate(lambda x, t: x, torch.zeros(3), 0)


def test_flow_matching_loss_is_the_mean_squared_velocity_error():
    """The loss is zero at the exact velocity and the element-wise mean squared error otherwise."""
    target = torch.randn(5, 8, 2)
    assert flow_matching_loss(target.clone(), target).item() == 0.0
    off = target.clone()
    off[0] += 2.0  # 16 of 80 elements off by 2
    assert torch.isclose(flow_matching_loss(off, target), torch.tensor(16 * 4 / 80))


def _multimodal(n: int, noise: float = 0.01) -> tuple[torch.Tensor, torch.Tensor]:
    """c ~ U(0,1); x | c an equal mixture of modes 0.2 + 0.3c, 0.5 and 0.9 - 0.2c, each +- noise."""
    c = torch.rand(n, 1)
    modes = torch.stack([0.2 + 0.3 * c[:, 0], torch.full((n,), 0.5), 0.9 - 0.2 * c[:, 0]], 1)
    return c, modes[torch.arange(n), torch.randint(0, 3, (n,))] + (2 * torch.rand(n) - 1) * noise


def test_critic_flow_extremum_queries_track_the_conditional_support():
    """Critic(0|c) is the conditional minimum, Critic(1|c) the maximum, Critic(0.5|c) the median mode."""
    torch.manual_seed(0)
    critic = Critic(cond_dim=1, num_critics=2, hidden_dims=(64, 64))
    opt = torch.optim.Adam(critic.parameters(), lr=3e-3)
    for _ in range(5000):
        loss = critic.loss(*_multimodal(256))
        opt.zero_grad()
        loss.backward()
        opt.step()
    c = torch.linspace(0.05, 0.95, 19)[:, None]
    with torch.no_grad():
        lo, mid, hi = (critic.query(c, eps, 20) for eps in (0.0, 0.5, 1.0))
        dist = critic.distance(c, 0.0, 20)
    assert lo.shape == (2, 19)
    # Each member separately finds the support's ends (the noise widens the modes by 0.01).
    assert (lo - (0.19 + 0.3 * c.T)).abs().mean(1).max() < 0.04, lo
    assert (hi - (0.91 - 0.2 * c.T)).abs().mean(1).max() < 0.04, hi
    assert ((lo < mid) & (mid < hi)).all() and (mid - 0.5).abs().max() < 0.06, mid
    # The sample mean (~0.53) would fail the extremum checks above; the ensemble is pessimistic (max).
    assert torch.equal(dist, lo.amax(0)) and (dist >= lo).all()


def test_heun_is_second_order():
    """dx/dt = x from 1 reaches e at t=1: Heun's error falls ~4x per halved step (Euler's ~2x), 5 Heun steps
    (10 evaluations) beat 20 Euler steps, a velocity linear in t is exact, and integrate() dispatches by name."""
    x0 = torch.ones(3, 1)

    def err(fn, n):
        return (fn(lambda x, t: x, x0, n) - math.e).abs().max().item()

    assert 3.5 < err(heun_integrate, 5) / err(heun_integrate, 10) < 4.5
    assert 1.8 < err(euler_integrate, 10) / err(euler_integrate, 20) < 2.2
    assert err(heun_integrate, 5) < err(euler_integrate, 20) / 3
    assert torch.allclose(heun_integrate(lambda x, t: 2 * t * torch.ones_like(x), x0, 3), x0 + 1)
    assert torch.equal(integrate(lambda x, t: x, x0, 4, "heun"), heun_integrate(lambda x, t: x, x0, 4))
    assert torch.equal(integrate(lambda x, t: x, x0, 4), euler_integrate(lambda x, t: x, x0, 4))
    with pytest.raises(ValueError, match="'rk4'"):
        integrate(lambda x, t: x, x0, 4, "rk4")
