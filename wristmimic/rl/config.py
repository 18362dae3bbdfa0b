"""PPO hyper-parameters: one dataclass, a docstring per field, and named presets.

``paper`` is InterMimic's teacher setting (``data/cfg/train/rlg/omomo.yaml``) at the WristMimic paper's scale;
``cpu`` is sized for a 2-core machine (see :data:`PRESETS` for why each value differs).
"""

from __future__ import annotations

import dataclasses
import json
import math
import types
import typing
from dataclasses import dataclass, replace
from typing import Any

from wristmimic.errors import InputError

SCHEDULES = ("fixed", "adaptive", "adaptive_update")
"""Learning-rate schedules of :class:`PPOConfig`."""
HELD_ACTIONS = ("none", "fingers")
"""Values of :attr:`PPOConfig.held_actions`."""
KL_SOURCES = ("approx", "update")
"""What ``adaptive_update`` adapts the rate to (:attr:`PPOConfig.kl_source`)."""


@dataclass(frozen=True)
class PPOConfig:
    """Proximal policy optimisation with GAE, separate actor/critic MLPs and a fixed action sigma."""

    num_envs: int = 2048
    """Parallel worlds of one scene."""
    horizon: int = 32
    """Environment steps per world between two updates (rollout length)."""
    minibatch_size: int = 8192
    """Samples per gradient step; ``num_envs * horizon`` must be a multiple of it."""
    epochs: int = 6
    """Passes over the rollout per update (InterMimic ``mini_epochs``)."""
    learning_rate: float = 2e-5
    """Adam step size: constant (``schedule = "fixed"``) or the starting value of the adaptive schedule."""
    schedule: str = "fixed"
    """``fixed`` learning rate, or ``adaptive`` (rsl_rl): after every minibatch step, lr / 1.5 where the
    approx KL exceeds 2 x ``desired_kl``, lr x 1.5 where it is below half of it, clamped to [lr_min, lr_max].
    ``adaptive_update``: the same rule once per update, on the update's mean approx KL (the logged
    ``loss/approx_kl``). Per minibatch, the first minibatch of every update measures KL 0 (the policy has not moved
    yet), so ``adaptive`` raises the rate x 1.5 at the start of every update: measured on the CPU recipe
    (``synth_default``, 32 worlds x 16 steps, 2 epochs x 2 minibatches) the four minibatches see median KL 0,
    0.003, 0.029 and 0.053, and the steps use 1.5, 2.25, 1.5 and 1 x 1e-5 while the rate logged after the update is
    the floor, 1e-5. Per update, the rate answers the KL that ``loss/approx_kl`` reports."""
    desired_kl: float = 0.01
    """Target approx KL of the adaptive schedule."""
    kl_source: str = "approx"
    """The KL that ``adaptive_update`` answers: ``approx``, the update's ``loss/approx_kl`` (CleanRL's estimator,
    mean over its minibatches before each step, on the minibatch's own sampled actions), or ``update``, the logged
    ``loss/kl_update``: the closed-form KL(old || new) of the Gaussian policies (rsl_rl's formula) after the whole
    update, averaged over every state of the rollout. From the second epoch on, ``approx`` is measured on samples
    the update has already fitted, which it overstates: on the CPU recipe (``synth_default``, first 30 updates)
    the update moved the policy by KL 0.008 (closed form, and the sample estimator on fresh actions from the old
    policy agrees: 0.008-0.009) while the same estimator on the rollout's own actions read 0.08-0.12 after the
    update and ``loss/approx_kl`` 0.02-0.04."""
    lr_min: float = 1e-5
    """Lower clamp of the adaptive learning rate."""
    lr_max: float = 1e-2
    """Upper clamp of the adaptive learning rate."""
    critic_learning_rate: float | None = None
    """A fixed Adam step size of its own for the critic (ProtoMotions: actor 2e-5, critic 1e-4); None: the critic
    shares the actor's (fixed or adaptive) rate. The CPU recipe of 2026-12-04 held the actor at its floor of 1e-5, so
    a shared critic learned at 1e-5 too. Measured with 1e-4 (400,384 frames, 256 quick trials, strict rule):
    synth_small_box seeds 0/1 92.6/100 % (shared rate 54.7/0 %), but synth_default seed 0 5.1 % (shared 93.8 %);
    so the recipe leaves this off (reports/recipe_levers_20261204/)."""
    log_std_learning_rate: float | None = None
    """A fixed Adam step size of its own for a learned log-std (``learn_std``); None: it shares the actor's rate.
    Adam moves a parameter by about its rate per step, so at the CPU recipe's adaptive 3-4e-5 and 4 steps per
    update sigma moves at most ~1e-4 in log per iteration (0.1000 -> 0.0999 in 1.1 M frames on the kettle). Measured
    with 1e-3 on sub2_largetable_000: 0.0999 -> 0.0994 in 139k frames, no faster, because the PPO gradient on the
    log-std changes sign between minibatches; so the recipe leaves this off."""
    held_actions: str = "none"
    """Action dimensions the policy does not act on: ``none``, or ``fingers``: every finger hinge is held at a = 0
    (the mid-range hand of ``env.finger_action``), with no noise and no share of the log-probabilities, entropy or
    KL. The adaptive rate spreads each update's KL evenly over the dimensions (measured on the kettle's body-only
    copy at 800k frames: 7.5e-5 per finger dimension, 7.6e-5 per body one), so on a clip whose fingers do nothing
    the 114 of 180 finger dimensions take 62 % of the trust region. For body-only studies."""
    gamma: float = 0.99
    """Discount factor."""
    lam: float = 0.95
    """GAE lambda (InterMimic ``tau``)."""
    clip: float = 0.2
    """PPO ratio clip epsilon (InterMimic ``e_clip``)."""
    value_coef: float = 5.0
    """Weight of the value loss 0.5 (V - R)^2 (InterMimic ``critic_coef``)."""
    clip_value_loss: bool = False
    """PPO2's clipped value loss: max((V - R)^2, (V_old + clip(V - V_old, +-clip) - R)^2)."""
    entropy_coef: float = 0.0
    """Weight of the entropy bonus (only moves a learned sigma)."""
    bounds_loss_coef: float = 10.0
    """Weight of the soft action-bound loss on the mean: sum_i max(|mu_i| - action_bound, 0)^2."""
    action_bound: float = 1.0
    """The soft bound on |mu| (actions are clipped to [-1, 1] by the environment)."""
    max_grad_norm: float = 1.0
    """Gradient-norm clip, applied to the actor and the critic separately."""
    normalize_advantage: bool = True
    """Standardise advantages per minibatch."""
    actor_hidden: tuple[int, ...] = (1024, 1024, 512)
    """Hidden widths of the actor MLP (SiLU)."""
    critic_hidden: tuple[int, ...] = (1024, 1024, 512)
    """Hidden widths of the critic MLP (SiLU)."""
    log_std: float = -2.9
    """Log sigma of the Gaussian policy: fixed (InterMimic: -2.9, sigma ~ 0.055), or the start of a learned one."""
    learn_std: bool = False
    """Learn a state-independent log sigma (rsl_rl) instead of keeping ``log_std`` fixed."""
    min_std: float = 0.0
    """Floor of a learned sigma (0: none)."""
    final_std: float = 0.0
    """Sigma annealing (DeepMimic anneals its exploration noise): > 0 moves a fixed sigma log-linearly from
    exp(``log_std``) to this value between ``std_anneal_start`` and ``std_anneal_end`` training frames, then
    holds it. The trained policy keeps the final sigma, which the evaluation protocol's sampled actions use.
    0: no schedule."""
    std_anneal_start: int = 0
    """Training frames at which the sigma schedule starts."""
    std_anneal_end: int = 0
    """Training frames at which the sigma schedule reaches ``final_std``."""
    deploy_std: float = 0.0
    """Sigma of the trained policy's Gaussian once deployed (evaluation's sampled actions, ``view --trial-seed``,
    periodic evaluation), separate from the exploration sigma of training, as TD3 separates exploration noise
    from its deployed policy; 0: the training sigma. Recorded in the run's config and the evaluation's
    ``eval.json``."""
    deploy_ema: float = 0.0
    """Deploy an exponential moving average of the policy (Polyak averaging: weights and observation normaliser)
    instead of the latest update's: after the k-th update, deployed <- d deployed + (1 - d) latest with
    d = min(deploy_ema, (1 + k) / (10 + k)) (TensorFlow's warm-up). It changes nothing in training; evaluation,
    ``view``, ``export`` and the periodic evaluation use the average (saved as ``deploy_policy`` in the
    checkpoint; ``ema_policy`` keeps the running average for a resume). 0: the latest weights. Measured because
    the deployed mean of the latest weights flipped between succeeding and failing from one periodic evaluation
    to the next (0, 81, 0, 6, 100, 0, 53 %) while the reward rose steadily. Measured on ``synth_high_table`` (seed 0, 256 quick trials): decay 0.95 deployed 72.7 % at
    iteration 100 and 3.5 % at 160, against 100 % and 0 % for the latest weights: it does not remove the swings."""
    deploy_best: bool = False
    """Deploy the policy of the periodic evaluation (``eval_every``) with the highest ``eval/strict_success_rate``
    and, among those, the highest ``eval/success_rate`` (ties: the later one; the latest or averaged weights until the first evaluation, and always with ``eval_every`` 0)
    instead of the last update's: model selection on a validation set of trials (``eval_base_seed``). Saved as ``deploy_policy`` with its
    iteration, frames and success rate (``deploy`` in the checkpoint); evaluation, ``view`` and ``export`` load
    it, resumed training goes on from the latest weights."""
    eval_base_seed: int | None = None
    """Base seed of the periodic evaluation's trials; None: the quick protocol's own (its first ``eval_trials``
    trials are those of ``wristmimic evaluate -p quick``). With ``deploy_best`` set it apart from the protocol's,
    so that the selection never sees the trials the final evaluation reports."""
    noise_correlation: float = 0.0
    """Temporal correlation rho of the exploration noise: eps_t = rho eps_(t-1) + sqrt(1 - rho^2) xi_t per world
    and action (an AR(1) process with a standard normal marginal, redrawn when an episode starts); 0: independent
    draws every step. The PD controller low-passes the actions, so independent noise explores slow corrections
    (a lean held over a second) with only sigma / sqrt(frames); rho = 0.9 keeps about sigma. The log-probabilities
    are those of the per-step marginal N(mu, sigma^2). The ``cpu`` recipe uses 0.9 (see its comment)."""
    obs_clip: float = 5.0
    """Normalised observations are clipped to [-obs_clip, obs_clip]."""
    max_frames: int = 200_000_000
    """Training budget in environment frames (all worlds together)."""
    checkpoint_every: int = 50
    """Write ``checkpoint.pt`` every this many iterations (and always at the end or on Ctrl-C); only matters when
    ``checkpoint_seconds`` > 0."""
    checkpoint_seconds: float = 0.0
    """Write ``checkpoint.pt`` after the first iteration of every start or resume and then whenever this many
    seconds have passed since the last one. 0 (the default): after every iteration, written in the background
    while the next one runs, so a kill loses at most the iteration being written and the one in progress; > 0
    (runs from before asynchronous checkpoints recorded 60): fewer writes, a kill loses up to this long."""
    eval_every: int = 0
    """Every this many iterations, run ``eval_trials`` frame-0 trials of the quick protocol with the current policy
    and log ``eval/success_rate`` (0: never)."""
    eval_trials: int = 32
    """Trials of each periodic evaluation (their frames do not count toward ``max_frames``)."""
    eval_confirm_trials: int = 0
    """With ``deploy_best``: a candidate whose ``eval_trials`` trials rank at least as high as the deployed policy's
    figures runs this many further trials (the selection protocol's next ones), and both rank by the rates over all
    their trials, so a lucky reading on a few trials no longer replaces a policy measured on more (the winner's
    curse of selecting the maximum of many small evaluations: on ``sub2_largetable_000`` the policy deployed for
    19 of 32 successes succeeded in 22.7 % of 256 quick trials). Logged as ``eval/confirm_success_rate`` and
    ``eval/confirm_strict_success_rate`` (all the candidate's trials; NaN where none ran). 0: off."""

    def __post_init__(self) -> None:
        batch = self.num_envs * self.horizon
        if not 0.0 <= self.noise_correlation < 1.0:
            raise InputError(None, "ppo.noise_correlation", f"{self.noise_correlation}", "a value in [0, 1)")
        if self.final_std < 0.0 or (self.final_std > 0.0 and (self.learn_std or self.final_std < self.min_std)):
            raise InputError(
                None, "ppo.final_std", f"{self.final_std}", "0 (no schedule), or >= min_std with learn_std off"
            )
        if not 0.0 <= self.deploy_ema < 1.0:
            raise InputError(
                None, "ppo.deploy_ema", f"{self.deploy_ema}", "0 (the latest weights) or a decay in (0, 1)"
            )
        if self.eval_confirm_trials < 0:
            raise InputError(None, "ppo.eval_confirm_trials", f"{self.eval_confirm_trials}", "0 (off) or a count > 0")
        if self.eval_base_seed is not None and not 0 <= self.eval_base_seed < 2**63:
            raise InputError(None, "ppo.eval_base_seed", f"{self.eval_base_seed}", "None or an integer in [0, 2^63)")
        if not (self.deploy_std >= 0.0 and math.isfinite(self.deploy_std)):
            raise InputError(None, "ppo.deploy_std", f"{self.deploy_std}", "0 (the training sigma) or a sigma > 0")
        if self.final_std > 0.0 and not 0 <= self.std_anneal_start <= self.std_anneal_end:
            raise InputError(
                None,
                "ppo.std_anneal_start/end",
                f"{self.std_anneal_start}..{self.std_anneal_end}",
                "0 <= start <= end (training frames)",
            )
        crit = self.critic_learning_rate
        if crit is not None and not 0.0 < crit < math.inf:
            raise InputError(None, "ppo.critic_learning_rate", f"{crit}", "None (the actor's rate) or a rate > 0")
        lr = self.log_std_learning_rate
        if lr is not None and not (self.learn_std and 0.0 < lr < math.inf):
            raise InputError(None, "ppo.log_std_learning_rate", f"{lr}", "None, or a rate > 0 with learn_std on")
        if self.held_actions not in HELD_ACTIONS:
            raise InputError(None, "ppo.held_actions", f"{self.held_actions!r}", f"one of {', '.join(HELD_ACTIONS)}")
        if self.schedule not in SCHEDULES:
            raise InputError(
                None, "ppo.schedule", f"unknown schedule {self.schedule!r}", f"one of {', '.join(SCHEDULES)}"
            )
        if self.kl_source not in KL_SOURCES:
            raise InputError(
                None, "ppo.kl_source", f"unknown KL source {self.kl_source!r}", f"one of {', '.join(KL_SOURCES)}"
            )
        if min(self.num_envs, self.horizon, self.minibatch_size, self.epochs, self.checkpoint_every) < 1:
            raise InputError(None, "ppo", "num_envs, horizon, minibatch_size, epochs, checkpoint_every must be >= 1")
        if not 0.0 <= self.checkpoint_seconds < math.inf:
            raise InputError(None, "ppo.checkpoint_seconds", f"{self.checkpoint_seconds}", "a finite number >= 0")
        if batch % self.minibatch_size:
            raise InputError(
                None,
                "ppo.minibatch_size",
                f"{self.minibatch_size} does not divide num_envs x horizon = {batch}",
                "a divisor of the rollout size",
            )

    @property
    def batch_size(self) -> int:
        """Samples per rollout: ``num_envs * horizon``."""
        return self.num_envs * self.horizon

    @property
    def sigma(self) -> float:
        """The initial (or fixed) sigma."""
        return math.exp(self.log_std)

    def log_std_at(self, frames: int) -> float:
        """Log sigma of the rollout collected after ``frames`` training frames (``log_std`` without a schedule)."""
        if self.final_std <= 0.0:
            return self.log_std
        span = self.std_anneal_end - self.std_anneal_start
        t = 1.0 if span <= 0 else min(max((frames - self.std_anneal_start) / span, 0.0), 1.0)
        return self.log_std + t * (math.log(self.final_std) - self.log_std)

    def ema_decay(self, updates: int) -> float:
        """Decay of the deployed average at the ``updates``-th update (1-based): ``deploy_ema`` with a warm-up."""
        return min(self.deploy_ema, (1.0 + updates) / (10.0 + updates))

    @property
    def min_log_std(self) -> float:
        return math.log(self.min_std) if self.min_std > 0 else -20.0


EVAL_SELECTION_SEED = 7_000_003
"""Base seed of the CPU recipe's periodic evaluation: its trials select the deployed policy (``deploy_best``), and
none of them is a trial of ``wristmimic evaluate``'s protocols (base seed 0)."""

PRESETS: dict[str, PPOConfig] = {
    # InterMimic's values at the paper's scale (2,048 worlds instead of InterMimic's 4,096; 8 minibatches).
    "paper": PPOConfig(),
    # The recommended CPU recipe (2 cores, ~700-1k frames/s). 32 worlds x 32 steps is a ~1.5 s rollout. With 153 action
    # dimensions and 1,707 observations, InterMimic's fixed lr and 6 epochs x 4 minibatches left the trust region
    # on every update (approx KL 1e5-1e14, clip fraction 0.8-0.9); measured on synth_default (40,960 frames,
    # residual actions): 5 epochs x 4 minibatches needed the adaptive lr to fall to 1.1e-6 to hold KL (median 0.017),
    # 2 epochs x 2 minibatches held a median KL of 0.02-0.03 and clip fraction 0.2 at lr ~1e-4, and the update
    # costs a fifth as much. Sigma is learned (rsl_rl) from 0.1 (0.05 rad on a body hinge at residual_scale 0.5;
    # at 200k frames sigma 0.1 reached 41 of 139 frames in frame-0 trials, 0.2 reached 35), with a clipped value
    # loss, and 32 frame-0 trials of the quick protocol every 20 iterations. The trained policy is deployed with
    # sigma 0.003: the same 300k-frame policy succeeded in 0 / 1.6 / 29.7 / 65.6 / 87.5 % of 64 quick-protocol
    # trials with sampled-action sigma 0.1 / 0.05 / 0.02 / 0.01 / 0.003 (a 614k-frame one: 0.8 % of 256 /
    # 50 / 70 / 94 / 98 %); annealing the training sigma itself to 0.003 over 250k frames stalled learning
    # (episodes of 15-19 frames, approx KL up to 47). The deployed mean of the latest weights swings between
    # succeeding and failing from one periodic evaluation to the next (synth_high_table, seed 0, 256 trials: 100 %
    # at iteration 100, 0 % at 160, 69 % at 180, 20 % at 196), so the recipe deploys the best of the periodic
    # evaluations (every 20,480 frames, on trials of their own) instead of the last update. Updates every 1,024
    # frames (32 worlds, minibatches of 512) instead of every 2,048 (64 worlds, 1,024): twice the updates per frame,
    # each held to the same KL by the adaptive rate (which settles one step lower, ~3e-5). On synth_default at 400k
    # frames (seeds 0/1/2, one machine, 256 quick trials) 64 worlds succeeded in 75.4/29.3/45.3 % (median approx KL
    # 0.023), 32 worlds in 100/100/100 % (median KL 0.027-0.035, above the 0.03, hence desired KL 0.008
    # instead of 0.01: seeds 0/1/2 97.3/90.2/92.2 %, median KL 0.019-0.021); 128 worlds (half the updates) 16.4 % for seed 2.
    # Exploration noise is temporally correlated (AR(1), rho 0.9): holding the box needs arm offsets of 0.15-0.4 rad
    # kept over many frames, which white noise of sigma 0.1 (0.05 rad) averages away through the PD controller; with
    # the object terms of 2026-12-04 seed 2 lifted the box by 245k frames and succeeded strictly in 98.4 % of 256
    # trials at 400k, where white noise never lifted it (0 %); reports/synth_default_machine2/noise_20261204/.
    # Rollouts of 16 steps (an update every 512 frames, minibatches of 256, periodic evaluation every 40 iterations,
    # still every 20,480 frames): the adaptive schedule holds the actor at its floor of 1e-5 from the third update on
    # (approx KL ~0.02 there), so the policy moves by about as much per update whatever the rollout's length, and
    # twice the updates per frame learn about twice as fast within the same trust region. At 400k frames (256 quick
    # trials, strict rule) with 32 steps: synth_default seeds 0/1/2 93.8/100/98.4 %, synth_small_box 54.7/0/93.8 %,
    # synth_turn seed 0 100 %, synth_high_table seed 0 100 %; with 16 steps: synth_default 100/100/100 % (seed 0's
    # first >= 90 % periodic evaluation at 163k frames instead of 266k), synth_small_box 100/100/100 %, but
    # synth_turn seed 0 0 % (the lift found at 327k, the turn not learned by 400k) and synth_high_table seed 0
    # 95.3 %; median approx KL 0.025-0.027, clip fraction 0.19-0.23; reports/recipe_levers_20261204/.
    # The adaptive rate starts at its floor, 1e-5, instead of 1e-4: Adam's first steps move every weight by about
    # the rate, and at 1e-4 the first update's approx KL was 3.6e4-3.1e9 (the schedule reached 1e-5 only at the
    # third update), a random jolt to the mean before any learning; from 1e-5 it is 0.14-0.28. At 400k frames (256
    # quick trials, strict rule) from 1e-5: synth_turn seeds 0/1 100 / 37.1 % (from 1e-4: 0 / 61.3 %),
    # synth_default seed 0 100 % (100 %), synth_small_box seed 1 100 % (100 %), synth_high_table seed 0 43.0 %
    # (95.3 %), the 1.55 m humanoid seed 0 100 % (not run): which runs pass changed, not how many. The first >= 90 %
    # periodic evaluation came at 266-389k frames or never (1e-4: 163-368k or never): the lift is still found late
    # and at a seed-dependent time.
    # One epoch of 4 minibatches of 128 per update, the rate adapted once per update to the closed-form KL between
    # the policy that collected the rollout and the updated one (``kl_source="update"``, desired 0.015: the band
    # 0.0075-0.03 is issue #14's bound), from 1.5e-5 (the mean step of the schedule before) with a floor of 1e-6.
    # Before, the per-minibatch rule answered CleanRL's sample estimator on minibatches the update had already
    # fitted (the second epoch), which overstated the update's KL ~2.5x (0.02-0.04 logged where the policy moved
    # by 0.008) and held the rate at its floor; per update and on the true KL the policy moves ~2x as far
    # (median ``loss/kl_update`` 0.014-0.017) while ``loss/approx_kl`` stays at 0.017-0.021 and the clip fraction at
    # 0.17-0.20. At 400k frames (Intel Xeon, 256 quick trials, strict rule; reports/recipe_update_kl_20261205/):
    # synth_default seeds 0/1/2 100 / 100 / 100 %, synth_small_box seed 1 100 %, synth_turn seeds 0/1 100 / 99.2 %,
    # synth_high_table seed 0 83.6 %, the 1.55 m humanoid seed 0 94.9 % (the recipe before, AMD EPYC: 100 / 100 / 100
    # / 100 / 100 / 37.1 / 43.0 / 100 %; turn seed 1 from scratch on the Intel machine: 0 % at 389k); first >= 90 %
    # periodic evaluation at 225-389k frames, so the lift is still found late for some seeds.
    "cpu": PPOConfig(
        num_envs=32,
        horizon=16,
        minibatch_size=128,
        epochs=1,
        learning_rate=1.5e-5,
        schedule="adaptive_update",
        kl_source="update",
        desired_kl=0.015,
        lr_min=1e-6,
        learn_std=True,
        log_std=math.log(0.1),
        min_std=0.02,
        deploy_std=0.003,
        noise_correlation=0.9,
        clip_value_loss=True,
        actor_hidden=(512, 256),
        critic_hidden=(512, 256),
        max_frames=5_000_000,
        checkpoint_every=80,
        eval_every=40,
        eval_trials=32,
        deploy_best=True,
        eval_base_seed=EVAL_SELECTION_SEED,
    ),
}

PRESET_ENV: dict[str, dict[str, Any]] = {
    # the paper's (InterMimic's) environment: absolute PD targets, uniform reference state initialisation and no
    # object curriculum; the CPU recipe uses EnvConfig's defaults (residual actions, failure-weighted starts,
    # virtual object controller)
    "paper": {
        "action_mode": "absolute",
        "velocity_feedforward": False,
        "starts": {"adaptive": False},
        "object_controller": {"enabled": False},
    },
    # the CPU recipe: EnvConfig's defaults, with
    # - the object rotation factor 10x the paper's (0.1 -> 1.0 per rad): at 0.1 a box tipped 90 deg still scores
    #   0.85 and policies carried it tipped (44-53 deg error at 600k frames);
    # - the object position factor 60x (5 -> 300 per m^2 of mean squared error over xyz: a 10 cm error on one axis
    #   scores 0.37 instead of 0.983) and episodes ended when the object's surface points are 10 cm off on average
    #   (InterMimic's 0.5 m never ends one on synth_default): without them no policy lifted the box, the box was
    #   left on the table or tipped and the paper's mean-error rule passed it anyway (strict success 0 % on every
    #   seed and variant); with both, synth_default seed 0 lifted it in 100 % of 256 trials at 400k frames
    #   (2026-12-04, reports/synth_default_machine2/carry_20261204/)
    "cpu": {"weights": {"orot": 1.0, "op": 300.0}, "termination": {"object_error": 0.1}},
}
"""Environment fields each preset sets (on top of the variant's), as plain values."""


def preset_env(name: str, variant: str) -> Any:
    """The environment config of ``variant`` under preset ``name`` (``EnvConfig``)."""
    from wristmimic.env.config import env_config_from_dict, overlay, variant_config

    if name not in PRESETS:
        raise InputError(None, "preset", f"unknown preset {name!r}", f"one of {', '.join(PRESETS)}")
    return env_config_from_dict(overlay(to_jsonable(variant_config(variant)), PRESET_ENV.get(name, {})))


def preset(name: str, **overrides: Any) -> PPOConfig:
    """A named preset (``paper``, ``cpu``) with fields replaced by ``overrides`` (``None`` values ignored).

    Changing ``num_envs`` or ``horizon`` without ``minibatch_size`` keeps the preset's number of minibatches.
    """
    if name not in PRESETS:
        raise InputError(None, "preset", f"unknown preset {name!r}", f"one of {', '.join(PRESETS)}")
    base = PRESETS[name]
    kw = {k: tuple(v) if isinstance(v, list) else v for k, v in overrides.items() if v is not None}
    unknown = sorted(set(kw) - {f.name for f in dataclasses.fields(PPOConfig)})
    if unknown:
        raise InputError(None, "ppo", f"unknown field(s) {', '.join(unknown)}", "PPOConfig fields")
    if "minibatch_size" not in kw and ("num_envs" in kw or "horizon" in kw):
        batch = kw.get("num_envs", base.num_envs) * kw.get("horizon", base.horizon)
        n_mb = base.batch_size // base.minibatch_size
        kw["minibatch_size"] = batch // n_mb if batch % n_mb == 0 else batch
    return replace(base, **kw)


# ----------------------------------------------------------------------------------- dataclass <-> JSON


def to_jsonable(obj: Any) -> Any:
    """Dataclasses (nested), tuples and paths as plain JSON values."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, list | tuple):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, float | int | str | bool) or obj is None:
        return obj
    return str(obj)


def _convert(hint: Any, value: Any) -> Any:
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        arms = [a for a in typing.get_args(hint) if a is not type(None)]
        return value if value is None else _convert(arms[0], value)
    if dataclasses.is_dataclass(hint) and isinstance(value, dict):
        return from_jsonable(hint, value)  # type: ignore[arg-type]
    if origin is tuple and isinstance(value, list):
        return tuple(value)
    return value


def from_jsonable(cls: type, data: dict[str, Any]) -> Any:
    """Rebuild a (nested) dataclass written by :func:`to_jsonable`; unknown keys raise :class:`InputError`."""
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise InputError(None, cls.__name__, f"unknown field(s) {', '.join(unknown)}")
    return cls(**{k: _convert(hints[k], v) for k, v in data.items()})


def dumps(obj: Any) -> str:
    """Stable JSON text of a config (sorted keys, indented)."""
    return json.dumps(to_jsonable(obj), indent=2, sort_keys=True)
