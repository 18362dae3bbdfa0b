"""PPO pieces on small crafted tensors: GAE, bounds loss, normaliser, Gaussian log-prob, storage, update, config."""

from __future__ import annotations

import math

import pytest
import torch

from wristmimic.env.config import EnvConfig, variant_config
from wristmimic.errors import InputError
from wristmimic.rl.config import PRESETS, PPOConfig, from_jsonable, preset, to_jsonable
from wristmimic.rl.networks import ActorCritic, ObsNormalizer
from wristmimic.rl.ppo import PPO, bounds_loss, compute_gae
from wristmimic.rl.storage import RolloutStorage
from wristmimic.scene import SceneConfig


def _gae_by_definition(r, v, term, tout, last, gamma, lam):
    """A_t = sum_k (gamma lam)^k delta_{t+k}, stopping after the first step that ends an episode."""
    H, N = r.shape
    adv = torch.zeros(H, N)
    for n in range(N):
        for t in range(H):
            total, discount = 0.0, 1.0
            for k in range(t, H):
                rk = r[k, n] + gamma * v[k, n] * tout[k, n]
                nxt = last[n] if k == H - 1 else v[k + 1, n]
                done = max(term[k, n], tout[k, n])
                total += discount * (rk + gamma * nxt * (1 - done) - v[k, n])
                if done:
                    break
                discount *= gamma * lam
            adv[t, n] = total
    return adv


def test_gae_matches_its_definition_with_terminations_and_time_outs() -> None:
    g = torch.Generator().manual_seed(0)
    H, N = 7, 3
    r, v, last = torch.rand(H, N, generator=g), torch.rand(H, N, generator=g), torch.rand(N, generator=g)
    term, tout = torch.zeros(H, N), torch.zeros(H, N)
    term[2, 0], tout[4, 1], tout[6, 2] = 1, 1, 1
    adv, ret = compute_gae(r, v, term, tout, last, 0.9, 0.8)
    torch.testing.assert_close(adv, _gae_by_definition(r, v, term, tout, last, 0.9, 0.8))
    torch.testing.assert_close(ret, adv + v)


def test_gae_bootstraps_time_outs_but_not_terminations() -> None:
    r, v, last = torch.zeros(1, 2), torch.full((1, 2), 5.0), torch.full((2,), 7.0)
    adv, _ = compute_gae(r, v, torch.tensor([[1.0, 0.0]]), torch.tensor([[0.0, 1.0]]), last, 0.5, 0.9)
    assert adv[0, 0] == pytest.approx(-5.0)  # terminated: 0 - V(s)
    assert adv[0, 1] == pytest.approx(0.5 * 5.0 - 5.0)  # timed out: gamma V(s_t) stands in for the lost state


def test_bounds_loss_is_zero_inside_and_quadratic_outside() -> None:
    assert bounds_loss(torch.tensor([[0.5, -1.0, 0.99]]), 1.0) == 0
    assert bounds_loss(torch.tensor([[1.5, -3.0]]), 1.0) == pytest.approx(0.25 + 4.0)


def test_obs_normalizer_equals_the_statistics_of_all_batches_and_round_trips() -> None:
    g = torch.Generator().manual_seed(1)
    batches = [torch.randn(n, 4, generator=g) * 3 + 2 for n in (5, 17, 1, 40)]
    norm = ObsNormalizer(4, clip=100.0)
    for b in batches:
        norm.update(b)
    x = torch.cat(batches).double()
    torch.testing.assert_close(norm.mean, x.mean(0))
    torch.testing.assert_close(norm.var, x.var(0, unbiased=False))
    other = ObsNormalizer(4, clip=100.0)
    other.load_state_dict(norm.state_dict())
    torch.testing.assert_close(other(x.float()), ((x - x.mean(0)) / x.std(0, unbiased=False)).float())
    assert ObsNormalizer(4, clip=1.0)(torch.full((1, 4), 50.0)).max() == 1.0


def test_log_prob_is_the_fixed_sigma_gaussian_and_sigma_is_not_learned() -> None:
    net = ActorCritic(6, 3, (16,), (16,), log_std=-2.9)
    mu, a = torch.randn(5, 3), torch.randn(5, 3)
    ref = torch.distributions.Normal(mu, math.exp(-2.9)).log_prob(a).sum(-1)
    torch.testing.assert_close(net.log_prob(mu, a), ref)
    assert "log_std" not in dict(net.named_parameters())
    actions, logp, mu0, value = net.act(torch.zeros(1000, 6), torch.Generator().manual_seed(0))
    assert (actions - mu0).std().item() == pytest.approx(math.exp(-2.9), rel=0.05)
    assert value.shape == logp.shape == (1000,)


def _filled_storage(net: ActorCritic, H: int = 4, N: int = 8) -> RolloutStorage:
    g = torch.Generator().manual_seed(2)
    st = RolloutStorage(H, N, net.obs_size, net.action_size)
    for _ in range(H):
        obs = torch.randn(N, net.obs_size, generator=g)
        a, lp, mu, v = net.act(obs, g)
        reward = (a[:, 0] > mu[:, 0]).float()  # acting above the mean on action 0 pays
        st.add(obs, a, lp, mu, v, reward, torch.zeros(N, dtype=torch.bool), torch.ones(N, dtype=torch.bool))
    return st


def test_storage_rejects_a_step_beyond_the_horizon_and_minibatches_cover_each_sample_once() -> None:
    net = ActorCritic(3, 2, (8,), (8,), -1.0)
    st = _filled_storage(net, H=3, N=4)
    with pytest.raises(RuntimeError, match="full"):
        st.add(*(torch.zeros(4, k) for k in (3, 2)), torch.zeros(4), torch.zeros(4, 2), *(torch.zeros(4),) * 4)
    st.observations = torch.arange(12.0).reshape(3, 4, 1).expand(3, 4, 3).clone()
    seen = [mb["observations"][:, 0] for mb in st.minibatches(4, 2, torch.Generator().manual_seed(0))]
    assert len(seen) == 6 and all(len(s) == 4 for s in seen)
    assert sorted(torch.cat(seen[:3]).tolist()) == list(range(12))


def test_update_moves_the_mean_toward_actions_with_positive_advantage() -> None:
    torch.manual_seed(0)
    net = ActorCritic(4, 2, (32,), (32,), log_std=-1.0)
    cfg = PPOConfig(num_envs=8, horizon=4, minibatch_size=16, epochs=4, learning_rate=1e-3, actor_hidden=(32,))
    alg = PPO(net, cfg)
    st = _filled_storage(net)
    alg.compute_returns(st, torch.zeros(8))
    before = net.actor(st.observations.flatten(0, 1))[:, 0].mean().item()
    losses = alg.update(st, torch.Generator().manual_seed(0))
    after = net.actor(st.observations.flatten(0, 1))[:, 0].mean().item()
    assert after > before + 0.01
    assert set(losses) >= {"loss/policy", "loss/value", "loss/bounds", "loss/approx_kl", "loss/clip_fraction"}
    assert all(math.isfinite(v) for v in losses.values())


def test_first_gradient_step_sees_ratio_one() -> None:
    net = ActorCritic(4, 2, (8,), (8,), log_std=-2.9)
    cfg = PPOConfig(num_envs=8, horizon=4, minibatch_size=32, epochs=1)
    st = _filled_storage(net)
    alg = PPO(net, cfg)
    alg.compute_returns(st, torch.zeros(8))
    losses = alg.update(st, torch.Generator().manual_seed(0))
    assert losses["loss/approx_kl"] == pytest.approx(0.0, abs=1e-6) and losses["loss/clip_fraction"] == 0.0


def test_presets_and_config_errors() -> None:
    paper = PRESETS["paper"]
    assert (paper.num_envs, paper.horizon, paper.minibatch_size, paper.epochs) == (2048, 32, 8192, 6)
    assert (paper.learning_rate, paper.gamma, paper.lam, paper.clip) == (2e-5, 0.99, 0.95, 0.2)
    assert paper.actor_hidden == (1024, 1024, 512) and paper.sigma == pytest.approx(0.055, abs=1e-3)
    small = preset("cpu", num_envs=10)  # keeps the preset's 4 minibatches
    assert small.batch_size // small.minibatch_size == PRESETS["cpu"].batch_size // PRESETS["cpu"].minibatch_size
    with pytest.raises(InputError, match="unknown preset"):
        preset("gpu")
    with pytest.raises(InputError, match="does not divide"):
        PPOConfig(num_envs=3, horizon=5, minibatch_size=4)


@pytest.mark.parametrize("cfg", [PRESETS["cpu"], variant_config("intermimic"), EnvConfig(), SceneConfig()])
def test_configs_round_trip_through_json(cfg) -> None:
    assert from_jsonable(type(cfg), to_jsonable(cfg)) == cfg
    with pytest.raises(InputError, match="unknown field"):
        from_jsonable(type(cfg), {**to_jsonable(cfg), "bogus": 1})


def test_adaptive_schedule_lowers_the_rate_above_twice_the_target_and_raises_it_below_half() -> None:
    net = ActorCritic(4, 2, (8,), (8,), log_std=-1.0)
    cfg = PPOConfig(num_envs=8, horizon=4, minibatch_size=32, schedule="adaptive", learning_rate=1e-3, lr_min=1e-4)
    alg = PPO(net, cfg)
    alg._adapt_learning_rate(0.05)
    assert alg.learning_rate == pytest.approx(1e-3 / 1.5)
    alg._adapt_learning_rate(0.001)
    assert alg.learning_rate == pytest.approx(1e-3)
    alg._adapt_learning_rate(0.015)  # inside [0.5, 2] x desired: unchanged
    assert alg.learning_rate == pytest.approx(1e-3)
    for _ in range(20):
        alg._adapt_learning_rate(1.0)
    assert alg.learning_rate == pytest.approx(1e-4)  # clamped
    with pytest.raises(InputError, match="schedule"):
        PPOConfig(schedule="cosine")


def test_adaptive_update_logs_rate_and_sigma_and_keeps_kl_near_the_target() -> None:
    torch.manual_seed(0)
    net = ActorCritic(4, 2, (32,), (32,), log_std=-1.0, learn_std=True, min_log_std=math.log(0.3))
    cfg = PPOConfig(num_envs=8, horizon=4, minibatch_size=8, epochs=4, schedule="adaptive", learning_rate=1e-1)
    alg = PPO(net, cfg)
    st = _filled_storage(net)
    alg.compute_returns(st, torch.zeros(8))
    losses = alg.update(st, torch.Generator().manual_seed(0))
    assert losses["loss/learning_rate"] < 1e-1  # a huge first step was cut back
    assert losses["loss/sigma"] >= 0.3 - 1e-6
    assert any(p is net.log_std_param for p in alg.optimizer.param_groups[0]["params"])


def test_per_update_schedule_keeps_one_rate_within_an_update_and_answers_its_mean_kl() -> None:
    """``adaptive_update``: every minibatch step of an update uses the same rate (``adaptive`` raises it at the first
    minibatch, whose KL is 0 by construction), and the next update's rate follows the logged mean approx KL."""

    def rates(schedule: str) -> tuple[list[list[float]], list[dict[str, float]]]:
        torch.manual_seed(0)
        net = ActorCritic(4, 2, (32,), (32,), log_std=-1.0)
        cfg = PPOConfig(
            num_envs=8, horizon=4, minibatch_size=8, epochs=2, schedule=schedule, learning_rate=3e-3, lr_min=1e-5
        )
        alg = PPO(net, cfg)
        used: list[list[float]] = []
        step = alg.optimizer.step

        def spy(*a, **kw):
            used[-1].append(alg.learning_rate)
            return step(*a, **kw)

        alg.optimizer.step = spy  # type: ignore[method-assign]
        logs = []
        for _ in range(3):
            st = _filled_storage(net)
            alg.compute_returns(st, torch.zeros(8))
            used.append([])
            logs.append(alg.update(st, torch.Generator().manual_seed(0)))
        return used, logs

    per_minibatch, _ = rates("adaptive")
    assert per_minibatch[0][0] == pytest.approx(3e-3 * 1.5)  # KL 0 at the first minibatch raised it
    per_update, logs = rates("adaptive_update")
    for u, log in zip(per_update, logs, strict=True):
        assert len(u) == 8 and len(set(u)) == 1 and log["loss/learning_rate"] == u[0]
    for prev, u in zip(logs[:-1], per_update[1:], strict=True):
        kl, lr = prev["loss/approx_kl"], prev["loss/learning_rate"]
        want = lr / 1.5 if kl > 0.02 else lr * 1.5 if kl < 0.005 else lr  # desired_kl 0.01
        assert u[0] == pytest.approx(max(want, 1e-5))
    assert any(a["loss/learning_rate"] != b["loss/learning_rate"] for a, b in zip(logs[:-1], logs[1:], strict=True))


def test_log_std_rate_of_its_own_moves_sigma_at_that_rate_outside_the_schedule() -> None:
    """With ``log_std_learning_rate`` the log-std is its own Adam group: the adaptive schedule moves the actor's
    rate only, and sigma moves about that rate per optimiser step (Adam), not the actor's."""

    def run(log_std_lr: float | None, schedule: str = "fixed") -> tuple[PPO, float]:
        torch.manual_seed(0)
        net = ActorCritic(4, 2, (32,), (32,), log_std=-1.0, learn_std=True)
        cfg = PPOConfig(
            num_envs=8,
            horizon=4,
            minibatch_size=8,
            epochs=2,
            schedule=schedule,
            learning_rate=1e-5,
            lr_min=1e-6,
            learn_std=True,
            log_std_learning_rate=log_std_lr,
        )
        alg = PPO(net, cfg)
        st = _filled_storage(net)
        alg.compute_returns(st, torch.zeros(8))
        alg.update(st, torch.Generator().manual_seed(0))
        return alg, float((net.log_std.detach() + 1.0).abs().max())

    _, moved_shared = run(None)
    _, moved_own = run(1e-2)
    steps = 2 * 4  # epochs x minibatches
    assert moved_shared <= steps * 1e-5 * 1.01
    assert 0.5e-2 < moved_own <= steps * 1e-2 * 1.01
    own, _ = run(1e-2, "adaptive")
    groups = own.optimizer.param_groups
    assert len(groups) == 2 and groups[-1]["params"] == [own.policy.log_std_param]
    assert groups[-1]["lr"] == 1e-2 and own.learning_rate != 1e-2
    with pytest.raises(InputError, match="log_std_learning_rate"):
        PPOConfig(log_std_learning_rate=1e-3)  # sigma is not learned
    with pytest.raises(InputError, match="log_std_learning_rate"):
        PPOConfig(learn_std=True, log_std_learning_rate=0.0)


def test_critic_rate_of_its_own_stays_fixed_while_the_schedule_moves_the_actor() -> None:
    """With ``critic_learning_rate`` the critic is an Adam group of its own: the adaptive schedule moves only the
    actor's rate, and each critic weight moves about the critic's rate per optimiser step (Adam)."""
    torch.manual_seed(0)
    net = ActorCritic(4, 2, (32,), (32,), log_std=-1.0)
    cfg = PPOConfig(
        num_envs=8,
        horizon=4,
        minibatch_size=8,
        epochs=2,
        schedule="adaptive",
        learning_rate=1e-5,
        lr_min=1e-6,
        critic_learning_rate=1e-2,
    )
    alg = PPO(net, cfg)
    before = [p.detach().clone() for p in net.critic.parameters()]
    st = _filled_storage(net)
    alg.compute_returns(st, torch.zeros(8))
    alg.update(st, torch.Generator().manual_seed(0))
    actor_group, critic_group = alg.optimizer.param_groups
    assert critic_group["lr"] == 1e-2 and alg.learning_rate != 1e-2
    assert all(any(p is q for q in critic_group["params"]) for p in net.critic.parameters())
    moved = max(float((p.detach() - b).abs().max()) for p, b in zip(net.critic.parameters(), before, strict=True))
    steps = 2 * 4  # epochs x minibatches
    assert 0.5e-2 < moved <= steps * 1e-2 * 1.01  # far beyond what the actor's ~1e-5 could move it
    for bad in (0.0, -1e-4, math.inf):
        with pytest.raises(InputError, match="critic_learning_rate"):
            PPOConfig(critic_learning_rate=bad)


def test_learned_sigma_is_a_parameter_with_a_floor_and_old_checkpoints_load() -> None:
    net = ActorCritic(6, 3, (16,), (16,), log_std=-1.0, learn_std=True, min_log_std=-2.0)
    assert "log_std_param" in dict(net.named_parameters())
    with torch.no_grad():
        net.log_std_param.fill_(-5.0)
    assert torch.equal(net.log_std, torch.full((3,), -2.0))
    fixed = ActorCritic(6, 3, (16,), (16,), log_std=-2.9)
    old = {("log_std" if k == "log_std_param" else k): v for k, v in fixed.state_dict().items()}
    again = ActorCritic(6, 3, (16,), (16,), log_std=0.0)
    again.load_state_dict(old)  # a checkpoint from before learned sigma stored 'log_std'
    assert torch.equal(again.log_std, torch.full((3,), -2.9))


def test_clipped_value_loss_is_never_below_the_plain_one() -> None:
    torch.manual_seed(0)
    losses = {}
    for clipped in (False, True):
        torch.manual_seed(0)
        net = ActorCritic(4, 2, (8,), (8,), log_std=-1.0)
        cfg = PPOConfig(num_envs=8, horizon=4, minibatch_size=32, epochs=1, clip_value_loss=clipped)
        st = _filled_storage(net)
        st.values += 3.0  # stale values far from the returns
        alg = PPO(net, cfg)
        alg.compute_returns(st, torch.zeros(8))
        losses[clipped] = alg.update(st, torch.Generator().manual_seed(0))["loss/value"]
    assert losses[True] >= losses[False]


def test_correlated_noise_is_standard_normal_per_step_with_lag_one_correlation_rho() -> None:
    from types import SimpleNamespace

    from wristmimic.rl.runner import Runner

    fake = SimpleNamespace(cfg=PPOConfig(num_envs=8, horizon=4, minibatch_size=32, noise_correlation=0.9))
    fake.gen = torch.Generator().manual_seed(0)
    fake.noise = torch.randn(4000, 3, generator=fake.gen)
    steps = []
    for _ in range(30):
        fake.noise = Runner._next_noise(fake)  # type: ignore[arg-type]
        steps.append(fake.noise)
    x = torch.stack(steps)  # (T, N, A)
    assert x.std().item() == pytest.approx(1.0, abs=0.02)
    lag1 = (x[1:] * x[:-1]).mean().item()
    assert lag1 == pytest.approx(0.9, abs=0.02)
    done = torch.zeros(4000, dtype=torch.bool)
    done[:2000] = True
    before = fake.noise.clone()
    Runner._restart_noise(fake, done)  # type: ignore[arg-type]
    assert torch.equal(fake.noise[2000:], before[2000:])
    assert abs((fake.noise[:2000] * before[:2000]).mean().item()) < 0.05  # redrawn, independent
    with pytest.raises(InputError, match="noise_correlation"):
        PPOConfig(noise_correlation=1.0)


def test_sigma_schedule_is_log_linear_between_its_frames_and_holds_after() -> None:
    cfg = PPOConfig(log_std=math.log(0.1), final_std=0.001, std_anneal_start=100, std_anneal_end=300)
    sig = lambda f: math.exp(cfg.log_std_at(f))  # noqa: E731
    assert sig(0) == pytest.approx(0.1) and sig(100) == pytest.approx(0.1)
    assert sig(200) == pytest.approx(0.01)  # half-way in log space
    assert sig(300) == pytest.approx(0.001) and sig(10_000) == pytest.approx(0.001)
    assert PPOConfig(log_std=-2.0).log_std_at(10**9) == -2.0  # no schedule: the fixed sigma
    for bad in (
        dict(final_std=-0.1),
        dict(final_std=0.01, learn_std=True),
        dict(final_std=0.01, min_std=0.02),
        dict(final_std=0.01, std_anneal_start=5, std_anneal_end=4),
    ):
        with pytest.raises(InputError, match="std"):
            PPOConfig(**bad)


def test_update_kl_is_the_closed_form_kl_of_the_whole_update_and_can_drive_the_schedule() -> None:
    """``loss/kl_update``: KL(old || new) of the two Gaussian policies averaged over the rollout's states (learned
    sigma included); the sample estimator on fresh actions of the old policy agrees with it, while
    ``loss/approx_kl`` on the rollout's own actions does not have to. ``kl_source=update`` adapts to it."""
    torch.manual_seed(0)
    net = ActorCritic(4, 3, (32,), (32,), log_std=-1.0, learn_std=True)
    cfg = PPOConfig(num_envs=8, horizon=4, minibatch_size=8, epochs=2, learning_rate=3e-3, learn_std=True)
    alg = PPO(net, cfg)
    st = _filled_storage(net)
    alg.compute_returns(st, torch.zeros(8))
    old_actor = [p.detach().clone() for p in net.actor.parameters()]
    old_log_std = net.log_std.detach().clone()
    out = alg.update(st, torch.Generator().manual_seed(0))
    obs = st.observations.flatten(0, 1)
    with torch.no_grad():
        mu_new, s_new = net.actor(obs), net.log_std.exp()
        mu_old, s_old = st.mu.flatten(0, 1), old_log_std.exp()
    old = torch.distributions.Normal(mu_old, s_old)
    new = torch.distributions.Normal(mu_new, s_new)
    want = torch.distributions.kl_divergence(old, new).sum(-1).mean()
    assert out["loss/kl_update"] == pytest.approx(float(want), rel=1e-5) and out["loss/kl_update"] > 1e-4
    assert any(not torch.equal(a, b) for a, b in zip(old_actor, net.actor.parameters(), strict=True))
    a = old.sample((4000,))  # fresh actions of the old policy: the k3 estimator's mean converges to the same KL
    log_ratio = (new.log_prob(a) - old.log_prob(a)).sum(-1)
    k3 = ((log_ratio.exp() - 1) - log_ratio).mean()
    assert float(k3) == pytest.approx(float(want), rel=0.15)
    # the per-update schedule on kl_update: the next rate follows the rule on that value
    cfg = PPOConfig(
        num_envs=8,
        horizon=4,
        minibatch_size=8,
        epochs=2,
        schedule="adaptive_update",
        kl_source="update",
        learning_rate=3e-3,
        lr_min=1e-6,
        desired_kl=1e-9,
    )
    alg = PPO(ActorCritic(4, 3, (32,), (32,), log_std=-1.0), cfg)
    st = _filled_storage(alg.policy)
    alg.compute_returns(st, torch.zeros(8))
    out = alg.update(st, torch.Generator().manual_seed(0))
    assert out["loss/kl_update"] > 2e-9 and alg.learning_rate == pytest.approx(3e-3 / 1.5)
    with pytest.raises(InputError, match="kl_source"):
        PPOConfig(kl_source="final")
