"""Networks: FiLM 1-D UNet, batched ensemble MLP flow, IMPALA encoder, observation encoder."""

import pytest
import torch
import torch.nn.functional as F

from lerobot_efm.flow import euler_integrate
from lerobot_efm.networks import (
    ConditionalUnet1d,
    EnsembleMLPFlow,
    FiLMResidualBlock1d,
    ImpalaEncoder,
    ImpalaResidualBlock,
    ObservationEncoder,
)


def small_unet(channels=3, cond_dim=5):
    return ConditionalUnet1d(channels, cond_dim, down_dims=(8, 16, 16), n_groups=4)


# --- ConditionalUnet1d ----------------------------------------------------------------------------


@pytest.mark.parametrize("length", [8, 16])
def test_unet_output_has_the_input_shape(length):
    """The velocity of a (B, L, C) trajectory is (B, L, C)."""
    net = small_unet()
    assert net(torch.randn(2, length, 3), torch.rand(2), torch.randn(2, 5)).shape == (2, length, 3)


def test_unet_rejects_lengths_not_divisible_by_the_downsampling():
    """L must be a multiple of 2**len(down_dims) (8 here); 12 is refused with a ValueError."""
    with pytest.raises(ValueError, match="12 is not divisible by 8"):
        small_unet()(torch.randn(2, 12, 3), torch.rand(2), torch.randn(2, 5))


def test_unet_routes_each_blocks_cached_film_to_that_block():
    """condition(c)[i] is exactly what the i-th executed block receives, and equals its own film_cond(c)."""
    net, c = small_unet(), torch.randn(2, 5)
    calls = []
    hooks = [
        m.register_forward_pre_hook(lambda m, args: calls.append((m, args[1])))
        for m in net.modules()
        if isinstance(m, FiLMResidualBlock1d)
    ]
    cache = net.condition(c)
    net.velocity(torch.randn(2, 8, 3), torch.tensor(0.3), cache)
    for h in hooks:
        h.remove()
    assert len(calls) == len(cache) == 3 * 2 + 2 + 3 * 2
    assert len({id(m) for m, _ in calls}) == len(calls)  # every block runs once
    for (block, film), cached in zip(calls, cache, strict=True):
        assert film is cached and torch.allclose(film, block.film_cond(c))


def test_unet_every_cached_film_entry_changes_the_output():
    """No cache entry is ignored: perturbing any block's conditioning changes the velocity."""
    net, x, t = small_unet(), torch.randn(2, 8, 3), torch.tensor(0.5)
    cache = net.condition(torch.randn(2, 5))
    base = net.velocity(x, t, cache)
    for i in range(len(cache)):
        bumped = [f + 0.5 if j == i else f for j, f in enumerate(cache)]
        assert not torch.allclose(net.velocity(x, t, bumped), base), i


def test_unet_cache_reused_across_euler_steps_matches_recomputing_it():
    """Integrating with one condition() cache equals calling forward (fresh conditioning) at each step."""
    net, c, x0 = small_unet(), torch.randn(4, 5), torch.randn(4, 8, 3)
    cache = net.condition(c)
    cached = euler_integrate(lambda x, t: net.velocity(x, t, cache), x0, 5)
    fresh = euler_integrate(lambda x, t: net(x, t, c), x0, 5)
    assert torch.allclose(cached, fresh, atol=1e-6)
    assert not torch.allclose(euler_integrate(lambda x, t: net(x, t, c + 1), x0, 5), fresh)  # c matters


def test_unet_scalar_time_equals_per_sample_time():
    """A 0-d t (Euler) gives the same velocity as a (B,) t holding that value; t matters."""
    net, x, c = small_unet(), torch.randn(3, 8, 3), torch.randn(3, 5)
    out = net(x, torch.tensor(0.3), c)
    assert torch.allclose(out, net(x, torch.full((3,), 0.3), c), atol=1e-6)
    assert not torch.allclose(out, net(x, torch.tensor(0.7), c))


def test_unet_gradient_reaches_every_parameter():
    """A regression loss gives every UNet parameter a non-zero gradient."""
    net = small_unet()
    out = net(torch.randn(4, 8, 3), torch.rand(4), torch.randn(4, 5))
    F.mse_loss(out, torch.randn_like(out)).backward()
    dead = [n for n, p in net.named_parameters() if p.grad is None or not p.grad.abs().sum() > 0]
    assert not dead, dead


# --- EnsembleMLPFlow -------------------------------------------------------------------------------


def reference_member(
    net: EnsembleMLPFlow, e: int, x: torch.Tensor, t: torch.Tensor, c: torch.Tensor
) -> torch.Tensor:
    """Member e written as a plain MLP on [x, t, c]: Linear, then (SiLU, LayerNorm, Linear) per hidden layer."""
    h = torch.cat([x, t.expand(x.shape[0], 1), c], -1)
    h = F.linear(h, net.weights[0][e].T, net.biases[0][e, 0])
    for i in range(1, len(net.weights)):
        h = F.layer_norm(F.silu(h), h.shape[-1:], net.norm_weights[i - 1][e, 0], net.norm_biases[i - 1][e, 0])
        h = F.linear(h, net.weights[i][e].T, net.biases[i][e, 0])
    return h


def test_ensemble_mlp_shapes_and_cached_conditioning():
    """(E, B, x_dim) in and out; condition() is (E, B, H1) and reusing it over Euler steps is exact."""
    net, c, x0 = EnsembleMLPFlow(3, 4, 6, (16, 16)), torch.randn(5, 6), torch.randn(3, 5, 4)
    cache = net.condition(c)
    assert cache.shape == (3, 5, 16) and net(x0, torch.tensor(0.2), c).shape == (3, 5, 4)
    cached = euler_integrate(lambda x, t: net.velocity(x, t, cache), x0, 4)
    assert torch.allclose(cached, euler_integrate(lambda x, t: net(x, t, c), x0, 4), atol=1e-6)


def test_ensemble_mlp_matches_a_plain_per_member_mlp():
    """Each member of the batched (split first layer) ensemble equals a plain MLP on [x, t, c]."""
    net, x, c = EnsembleMLPFlow(3, 4, 6, (16, 8)), torch.randn(3, 5, 4), torch.randn(5, 6)
    with torch.no_grad():  # non-trivial LayerNorm affine parameters
        for p in [*net.norm_weights, *net.norm_biases]:
            p.normal_()
    t_scalar, t_rows = torch.tensor(0.37), torch.rand(3, 5, 1)
    out_scalar, out_rows = net(x, t_scalar, c), net(x, t_rows, c)
    for e in range(3):
        assert torch.allclose(
            out_scalar[e], reference_member(net, e, x[e], t_scalar.reshape(1, 1), c), atol=1e-5
        )
        assert torch.allclose(out_rows[e], reference_member(net, e, x[e], t_rows[e], c), atol=1e-5)


def test_ensemble_members_are_independent():
    """Perturbing member 0's weights changes member 0's output only."""
    net, x, t, c = (
        EnsembleMLPFlow(3, 4, 6, (16, 16)),
        torch.randn(3, 5, 4),
        torch.tensor(0.5),
        torch.randn(5, 6),
    )
    before = net(x, t, c).detach()
    with torch.no_grad():
        for p in [*net.weights, *net.biases, *net.norm_weights, *net.norm_biases]:
            p[0] += 0.3 * torch.randn_like(p[0])
    after = net(x, t, c).detach()
    assert not torch.allclose(after[0], before[0]) and torch.equal(after[1:], before[1:])


# --- Encoders --------------------------------------------------------------------------------------


@pytest.mark.parametrize("size", [128, 32])
def test_impala_output_shape_and_leading_dims(size):
    """(B, 3, H, W) -> (B, out_dim); (B, T, 3, H, W) -> (B, T, out_dim), each frame encoded alone."""
    enc = ImpalaEncoder((3, size, size), out_dim=16, channels=(4, 8, 8), hidden_dim=16).eval()
    images = torch.rand(2, 3, 3, size, size)
    assert enc(images[:, 0]).shape == (2, 16)
    out = enc(images)
    assert out.shape == (2, 3, 16) and torch.allclose(out[1, 2], enc(images[1, 2][None])[0], atol=1e-5)


def test_impala_channels_last_is_a_speed_choice_only():
    """The encoder runs channels-last; its output is the plain channels-first network's (same weights)."""
    enc = ImpalaEncoder((3, 32, 32), out_dim=16, channels=(4, 8, 8), hidden_dim=16).eval()
    images = torch.rand(3, 3, 32, 32)
    plain = enc.head(enc.stacks(images - 0.5))
    assert torch.allclose(enc(images), plain, atol=1e-5)


def test_impala_default_flattens_128px_to_8192_features():
    """The reference IMPALA-small turns 128x128 images into 32*16*16 = 8192 features before its MLP."""
    enc = ImpalaEncoder((3, 128, 128))
    assert enc.head[2].normalized_shape == (8192,) and enc.head[3].in_features == 8192


def test_impala_residual_blocks_use_two_distinct_trained_convs():
    """Each residual block has its own conv1 and conv2 (the reference reuses one), both get gradients."""
    enc = ImpalaEncoder((3, 32, 32), out_dim=16, channels=(4, 8, 8), hidden_dim=16)
    blocks = [m for m in enc.modules() if isinstance(m, ImpalaResidualBlock)]
    assert len(blocks) == 3
    enc(torch.rand(2, 3, 32, 32)).square().sum().backward()
    for b in blocks:
        assert b.conv1 is not b.conv2 and not torch.equal(b.conv1.weight, b.conv2.weight)
        assert b.conv1.weight.grad.abs().sum() > 0 and b.conv2.weight.grad.abs().sum() > 0


def observation_encoder(state_encoder="identity", **kwargs):
    return ObservationEncoder(
        {"images.top": (3, 32, 32)},
        {"state": 2, "environment_state": 3},
        8,
        (4, 8, 8),
        16,
        0.2,
        state_encoder,
        12,
        **kwargs,
    ).eval()


def observation(prefix="observation."):
    return {
        prefix + "images.top": torch.rand(4, 3, 32, 32),
        prefix + "state": torch.randn(4, 2),
        prefix + "environment_state": torch.randn(4, 3),
    }


def test_observation_encoder_concatenates_images_then_sorted_vectors():
    """Identity latents are [camera latent, environment_state, state] and latent_dim = 8 + 3 + 2."""
    enc, obs = observation_encoder(), observation()
    out = enc(obs)
    assert enc.latent_dim == 13 and out.shape == (4, 13)
    assert torch.allclose(out[:, :8], enc.images["images__top"](obs["observation.images.top"]))
    assert torch.equal(out[:, 8:11], obs["observation.environment_state"]) and torch.equal(
        out[:, 11:], obs["observation.state"]
    )


def test_observation_encoder_reads_mirrored_keys_with_the_same_weights():
    """forward(batch, "observation.goal.") encodes goal keys exactly like the same values as observations."""
    enc, obs = observation_encoder("mlp"), observation()
    goal = {k.replace("observation.", "observation.goal."): v for k, v in obs.items()}
    assert torch.allclose(enc(goal, "observation.goal."), enc(obs))
    with pytest.raises(KeyError, match="observation.goal.images.top"):
        enc(obs, "observation.goal.")


def test_observation_encoder_mlp_size_and_invalid_choice():
    """ "mlp" encodes each vector key to state_latent_dim; an unknown state_encoder raises ValueError."""
    enc = observation_encoder("mlp")
    assert enc.latent_dim == 8 + 2 * 12 and enc(observation()).shape == (4, 32)
    with pytest.raises(ValueError, match="state_encoder.*'conv'"):
        observation_encoder("conv")


def test_observation_encoder_fourier_features():
    """ "fourier" keeps each coordinate and appends sin/cos(2^k pi x), k < K: (1 + 2K) features a coordinate."""
    enc = observation_encoder("fourier", state_fourier_frequencies=3)
    assert enc.latent_dim == 8 + (3 + 2) * 7
    obs = observation()
    obs["observation.state"] = torch.tensor([[0.5, -0.25]]).expand(4, 2)
    state = enc(obs)[:, 8 + 3 * 7 :]  # vector keys sorted: environment_state, then state
    x = torch.tensor([0.5, -0.25])
    angles = (x[:, None] * torch.pi * torch.tensor([1.0, 2.0, 4.0])).flatten()
    assert torch.allclose(state[0], torch.cat([x, angles.sin(), angles.cos()]), atol=1e-6)
    assert torch.allclose(state[0, 2], torch.tensor(1.0))  # sin(pi / 2)


@pytest.mark.parametrize("kernel,stride,padding", [(3, 1, 1), (3, 2, 1), (1, 1, 0)])
@pytest.mark.parametrize("length", [1, 2, 8, 16])
def test_temporal_conv_gemm_path_equals_the_convolution(kernel, stride, padding, length):
    """The small-batch inference path (one GEMM over windows) computes exactly nn.Conv1d."""
    from lerobot_efm.networks import TemporalConv1d

    conv = TemporalConv1d(6, 5, kernel, stride=stride, padding=padding)
    x = torch.randn(2, 6, length)
    with torch.no_grad():
        fast = conv(x)
    assert torch.allclose(fast, torch.nn.Conv1d.forward(conv, x), atol=1e-5)


@pytest.mark.parametrize("kernel,stride,padding", [(3, 1, 1), (3, 2, 1), (1, 1, 0)])
@pytest.mark.parametrize("length", [2, 8, 16])
def test_temporal_conv_trains_on_the_cpu_through_the_gemm_path(kernel, stride, padding, length):
    """CPU training runs the GEMM path (faster, bench_temporal_conv.py) with nn.Conv1d's outputs and gradients."""
    from lerobot_efm.networks import TemporalConv1d

    conv = TemporalConv1d(6, 5, kernel, stride=stride, padding=padding)
    x = torch.randn(64, 6, length, requires_grad=True)
    out = conv(x)
    assert "Convolution" not in type(out.grad_fn).__name__  # the GEMM path, not the regular convolution
    weights = torch.randn_like(out)
    grads = torch.autograd.grad((out * weights).sum(), (x, conv.weight, conv.bias))
    expected = torch.nn.Conv1d.forward(conv, x)
    assert torch.allclose(out, expected, atol=1e-5)
    expected_grads = torch.autograd.grad((expected * weights).sum(), (x, conv.weight, conv.bias))
    for got, want in zip(grads, expected_grads, strict=True):
        assert torch.allclose(got, want, atol=1e-4)
