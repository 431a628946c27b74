"""Schema of an agent preset (`agents/*.yaml`): the policy network and PPO's hyperparameters.

Defaults follow CleanRL's `ppo_continuous_action.py`, which in turn follows the 37
implementation details of PPO (Huang et al., 2022).
"""

from __future__ import annotations

import importlib.util
from typing import Any, Literal

from pydantic import Field, model_validator

from taskforge.spec.common import StrictModel


class PolicySpec(StrictModel):
    type: Literal["mlp", "lstm", "gru"] = "mlp"
    """`mlp`: feed-forward; `lstm` / `gru`: a recurrent core before the MLP (RL² uses `gru`)."""
    hidden_sizes: list[int] = Field(default_factory=lambda: [256, 256])
    """Widths of the MLP (after the core for recurrent types, where `[]` puts the action and
    value heads straight on the core's output, as Meta-World+'s RL²)."""
    activation: Literal["tanh", "relu", "elu"] = "tanh"
    recurrent_size: int = Field(default=128, ge=1)
    """Width of the LSTM or GRU core (recurrent policies only)."""
    encoder_sizes: list[int] = Field(default_factory=list)
    """Recurrent policies: an MLP of these widths (`activation` after each layer) between the
    input and the core; empty = the core reads the raw input. Meta-World+'s RL² encodes its input
    with 3 x 256 tanh layers before a 256-unit GRU (`agents/rl2_mwplus.yaml`)."""
    action_bounds: Literal["clip", "squash"] = "clip"
    """How Gaussian samples meet the action box: `clip` at the env boundary (CleanRL) or `squash`
    with tanh (log-prob corrected)."""
    init_log_std: float = Field(default=0.0, ge=-5.0, le=2.0)

    @model_validator(mode="after")
    def _positive_sizes(self) -> PolicySpec:
        for name in ("hidden_sizes", "encoder_sizes"):
            if any(h < 1 for h in getattr(self, name)):
                raise ValueError(f"'{name}' must all be >= 1 (got {getattr(self, name)})")
        if not self.hidden_sizes and self.type == "mlp":
            raise ValueError("an mlp policy needs at least one layer in 'hidden_sizes'")
        if self.encoder_sizes and self.type == "mlp":
            raise ValueError("'encoder_sizes' is for recurrent policies (type 'gru' or 'lstm'); an mlp has only 'hidden_sizes'")
        return self


class PPOSpec(StrictModel):
    num_envs: int = Field(default=8, ge=1, le=1024)
    rollout_steps: int = Field(default=256, ge=1)
    """Steps per environment per update; batch size = num_envs * rollout_steps."""
    learning_rate: float = Field(default=3e-4, gt=0.0, le=1.0)
    anneal_lr: bool = True
    gamma: float = Field(default=0.99, ge=0.0, le=1.0)
    gae_lambda: float = Field(default=0.95, ge=0.0, le=1.0)
    update_epochs: int = Field(default=10, ge=1)
    num_minibatches: int = Field(default=32, ge=1)
    clip_coef: float = Field(default=0.2, gt=0.0)
    clip_vloss: bool = True
    ent_coef: float = Field(default=0.0, ge=0.0)
    vf_coef: float = Field(default=0.5, ge=0.0)
    max_grad_norm: float = Field(default=0.5, gt=0.0)
    target_kl: float | None = Field(default=None, gt=0.0)
    norm_adv: bool = True
    norm_obs: bool = True
    norm_reward: bool = True
    bptt_length: int | None = Field(default=None, ge=1)
    """Recurrent policies: the update re-runs the rollout in chunks of this many steps, each from
    the hidden state recorded when it was collected (truncated backprop through time); default
    the whole rollout. Must divide `rollout_steps`."""

    @property
    def num_sequences(self) -> int:
        """Sequences a recurrent update shuffles: `num_envs` times the chunks per rollout."""
        return self.num_envs * (self.rollout_steps // (self.bptt_length or self.rollout_steps))

    @model_validator(mode="after")
    def _minibatches_fit(self) -> PPOSpec:
        batch = self.num_envs * self.rollout_steps
        if self.num_minibatches > batch:
            raise ValueError(
                f"'num_minibatches' ({self.num_minibatches}) exceeds the batch "
                f"num_envs*rollout_steps = {batch}"
            )
        if self.bptt_length is not None and self.rollout_steps % self.bptt_length:
            raise ValueError(
                f"'bptt_length' ({self.bptt_length}) must divide 'rollout_steps' ({self.rollout_steps})"
            )
        return self


class RL2Spec(StrictModel):
    """RL² (Duan et al., 2016): a trial is `trial_episodes` episodes on one task and goal; the
    recurrent state persists across its episodes and resets between trials."""

    trial_episodes: int = Field(default=10, ge=1, le=1000)
    """K, the episodes per trial. Meta-test runs one trial of K episodes per held-out goal."""
    reward_input_scale: float = Field(default=1.0, gt=0.0, le=1000.0)
    """The previous reward enters the policy's input multiplied by this (what the agent learns
    from is the unscaled reward). With `ppo.norm_obs` the input is normalised anyway;
    Meta-World+ feeds raw inputs and scales the reward by 0.1 (V2 rewards are 0-10 per step):
    per its paper, an unbounded reward in the recurrent state makes RL² collapse."""


# The fields that act on the terminal value, and how: each set away from its default means
# nothing without one (`MPCSpec._consistent` names the field and this in its error).
_SHAPES_THE_VALUE: dict[str, str] = {
    "value_refit_every": "refits the terminal value",
    "value_ensemble": "gives the terminal value heads",
    "value_pessimism": "weighs the terminal value's heads",
    "value_start": "delays the terminal value",
    "value_bound": "clips the terminal value's targets",
    "value_relabel": "widens the terminal value's rows",
    "value_updates": "fits the terminal value",
    "value_policy": "is the terminal value's kind",
}


class MPCSpec(StrictModel):
    """`algo: mpc`: a learned dynamics model and model-predictive control (PETS, Chua et al.
    2018). An ensemble of probabilistic networks predicts the next observation and the stage
    reward; at every step a planner searches action sequences of `horizon` steps through the
    model and the first action of the best is executed. Defaults: PETS's design (an ensemble of
    5, CEM with momentum 0.1, one model per particle for the whole horizon) at sizes 2 CPU cores
    plan in about 10 ms a step (benchmarks/RESULTS.md, "Model-based")."""

    ensemble_size: int = Field(default=5, ge=1, le=64)
    hidden_sizes: list[int] = Field(default_factory=lambda: [200, 200, 200], min_length=1)
    """PETS: 4 x 200 (a CPU plans with fewer: agents/mpc.yaml uses 2 x 128)."""
    learning_rate: float = Field(default=1e-3, gt=0.0)
    weight_decay: float = Field(default=5e-5, ge=0.0)
    """L2 on the model's weights (PETS used 2.5e-5 to 1e-4 by layer)."""
    nll_beta: float = Field(default=0.0, ge=0.0, le=1.0)
    """β-NLL (Seitzer et al. 2022): each observation dimension's negative log-likelihood
    weighted by its predicted variance to the power β. 0: PETS's plain likelihood, under which
    the hand and puck of Meta-World went unlearnt (taskforge/agents/dynamics.py); 0.5: the paper's advice
    and agents/mpc_beta.yaml's; 1: the mean learns as by squared error."""
    batch_size: int = Field(default=256, ge=1)
    model_updates: int = Field(default=200, ge=1)
    """Gradient steps on the model after each collection of `steps_per_update` env steps."""
    value_updates: int | None = Field(default=None, ge=1)
    """Gradient steps on the terminal value (V, or Q and pi) after each collection; None: as
    many as `model_updates`. Why apart from the model's: TD-MPC2 takes one value step per env
    step (an update-to-data ratio of 1), 5x the model's 200 per 1,000 here, and a value fitted
    that much less may trail its data: push seed 0's 200k policy value (0.74 held-out) fitted on
    for 20k more steps on its own buffer, nothing else changed, planned 0.88 (60k more: 0.72);
    live on that seed, one step per env step (agents/mpc_policy_value_utd.yaml) planned 0.68 at
    60k, 0.90 at 120k and 0.92 at 200k (benchmarks/RESULTS.md). Needs `terminal_value`."""
    steps_per_update: int = Field(default=1000, ge=1)
    """Env steps (all envs together) between model fits."""
    random_steps: int = Field(default=2000, ge=0)
    """The first `random_steps` env steps take uniformly random actions (PETS's random first
    trial), the model fitted every `steps_per_update` meanwhile; none where the data came from
    elsewhere (a warm start's demos, `init_from`'s buffer)."""
    buffer_size: int = Field(default=1_000_000, ge=1000)
    planner: Literal["cem", "mppi", "random_shooting"] = "cem"
    """`random_shooting`: the best of `population` uniform sequences (as GenReL-World describes);
    `cem`: `iterations` rounds of refitting a Gaussian to the `elites` best (PETS); `mppi`:
    `iterations` rounds of an exponentially return-weighted mean (Williams et al. 2017)."""
    horizon: int = Field(default=15, ge=1, le=200)
    population: int = Field(default=200, ge=2)
    elites: int = Field(default=20, ge=1)
    iterations: int = Field(default=4, ge=1)
    particles: int = Field(default=5, ge=1)
    """Rollouts per candidate sequence, particle p through ensemble member p mod ensemble_size
    for the whole horizon (PETS's TS-inf); the candidate's score is their mean return (plus
    `optimism` x their std)."""
    optimism: float = 0.0
    """Weight of the spread of a candidate's particle returns in its score: mean + optimism x
    std. > 0 favours sequences whose outcome the members disagree on (optimism in the face of
    uncertainty); < 0 avoids them (the pessimism of offline model-based RL). Why it exists: on
    push, a seed whose early search rarely pushed the puck toward the goal never took off, and
    optimism was the hope of sending the search to contact; measured, it did not, since the
    members disagree most away from the puck (benchmarks/RESULTS.md). 0: PETS's mean. Needs
    `particles` >= 2."""
    init_std: float = Field(default=0.5, gt=0.0)
    """The sampling distribution's std (actions in [-1, 1]) at each step's first iteration."""
    momentum: float = Field(default=0.1, ge=0.0, lt=1.0)
    """CEM: weight of the previous iteration's mean and std in the refit (PETS's alpha)."""
    temperature: float = Field(default=1.0, gt=0.0)
    """MPPI: lambda, in units of the candidates' return std (so it does not depend on the reward's scale)."""
    discount: float = Field(default=1.0, gt=0.0, le=1.0)
    terminal_value: bool = False
    """Add `discount^horizon * V(last state)` to each particle's predicted return, V fitted by
    TD(0) on the buffer (agents/value.py: LOOP's and TD-MPC's fix for a planner that sees too few
    steps). Needs `discount` < 1."""
    value_tau: float = Field(default=0.005, gt=0.0, le=1.0)
    """Polyak rate of V's target network, per gradient step."""
    value_refit_every: int = Field(default=0, ge=0)
    """Env steps between fresh refits of V: at the first fit and whenever the step count has passed
    another multiple of this, V (and its optimizer) starts again from new weights and takes
    `value_refit_updates` TD(0) steps on the whole buffer at once; the fits between go on from it.
    Why: a V fitted online follows its targets while they grow tens of times over and keeps what
    the early data taught it (the primacy bias that Nikishin et al. 2022 reset networks against);
    on pick-place at 400k the same model and planner placed 0.28 of 50 held-out goals with the
    online V and 0.50 with one refitted on the final buffer (benchmarks/RESULTS.md). It can hurt
    once most episodes succeed: push seed 1's refit at 100k fell to 0.16 (one V) and 0.12 (5
    heads); with the model fixed, the value from before it planned 0.77 of 30 goals, the
    refitted one 0.33, and with `value_policy` the refit at 50k threw away a Q that had started to
    push (0.34 held-out at 40k, 0.06 at 60k after it). A period longer than the run refits at the
    first fit only, TD-MPC's arrangement (`agents/mpc_policy_value.yaml`). 0: never, V is fitted
    online only (no fresh first fit either). Needs `terminal_value`."""
    value_ensemble: int = Field(default=1, ge=1)
    """Heads of V, each fitted by TD(0) on its own bootstrap draw of the data against its own
    target head (bootstrapped DQN, Osband et al. 2016), so they disagree where the data says
    little; plans score a last state by their mean (minus `value_pessimism` x their std). Why:
    one V refitted on push seed 1's 100k data planned 0.20 of 30 held-out goals, single heads
    0.30 and 0.47, the mean of 5 heads 0.60 (with the run's 130k model; live, they fell at that
    refit as one V did: benchmarks/RESULTS.md). 1: one V. Needs `terminal_value`."""
    value_pessimism: float = Field(default=0.0, ge=0.0)
    """Weight of the value heads' std subtracted from their mean in a plan's score (a lower
    confidence bound, as LOOP and MOPO plan on, against a planner seeking the states V
    overrates). Measured on that push data it did not add to the mean (0.53 at 1 and 2 std, 0.60
    at 0). 0: the heads' mean. Needs `value_ensemble` >= 2."""
    value_refit_updates: int = Field(default=40_000, ge=1)
    """TD(0) steps of each fresh refit (40k: what the measured offline refit took; 2-13 min on 2
    CPU cores at 3 x 256 as the machine's speed varies between sessions, one V or 5 heads alike)."""
    value_policy: bool = False
    """Score a plan's last state by `Q(s, pi(s))` of a policy `pi` fitted on the buffer by TD3+BC
    (TD-MPC's value, Hansen et al. 2022; agents/policy_value.py) instead of V, the value of the
    data's behaviour; with `prior_trajectories`, `pi`'s rollouts are the proposals (no warm start
    needed). Fitted like V: `model_updates` steps per fit, afresh at each `value_refit_every`.
    Why: with push seed 1's model and search fixed, every V refitted on its first 100k
    transitions planned 0.10-0.30 of 30 held-out goals, this Q 0.60 and with 5 of pi's rollouts
    proposed 0.87 (benchmarks/RESULTS.md). Needs `terminal_value`; not with `value_ensemble`."""
    value_bound: bool = False
    """Clip each TD target to the fitted rows' reward range over (1 - discount), `[min r, max r] /
    (1 - discount)`: no value of this reward can leave it (termination is not modelled), and a
    bootstrap that has started to climb cannot feed its own growth past it. Why: on push seed 0,
    the first fresh fit of `value_policy` (40k TD3+BC steps on 1,000 random rows, worth ~18) held
    Q in range to 20k steps and then ran it away to ~210, both Q heads together; the planner,
    weighing that Q against ~1 of reward over its horizon, never learnt reach in 19k steps where
    seed 1 had by 15k. Refitted offline on the same rows with the bound: Q's mean 28 at 40k (the
    bound 8.4-50.7; benchmarks/RESULTS.md). Needs `terminal_value`."""
    value_start: int = Field(default=0, ge=0)
    """Env steps before the terminal value's first fit: until then it is neither fitted nor used,
    plans score the model's rewards alone, and with `value_policy` its pi proposes nothing. Why:
    fitted on the first 1,000 random rows, push seed 0's Q ranked the planner's later states
    against their reward (correlation -0.2 to -0.34 on rows 20k-25k, after 2k-40k TD3+BC steps),
    and with it the planner reached 0.00-0.60 of 10 held-out reach goals where the same model with
    rewards alone reached 1.00; fitted afresh on the first 20,000 rows, Q's correlation was 0.94
    and the planner reached 0.90 (benchmarks/RESULTS.md). A value's first rows should cover where
    the planner goes. 0: from the first fit."""
    value_relabel: bool = False
    """After a promotion, the value also fits the earlier stages' rows, each with the reward the
    model's reward network (its members' mean) predicts there for the stage being trained; the
    stage's own rows keep their stored reward. Why: the value fits the stage being trained's rows
    (their stored reward is that stage's), so a first fit soon after a promotion sees few rows
    (push seed 0: 4,400 at 20k, its 15,600 reach rows left out), and a Q converged on them pulled
    the hand off the puck; the reach rows cover the approach to it. Fitted offline on push seed
    0's first 20,000 rows so relabelled, Q's correlation with the reward on the planner's rows
    35k-40k was 0.64-0.77 (the push rows alone: 0.46-0.54) and the planner pushed 0.20-0.30 of
    10 held-out goals (push rows alone 0.00-0.10; benchmarks/RESULTS.md). Needs `terminal_value`."""
    value_policy_alpha: float = Field(default=2.5, gt=0.0)
    """TD3+BC's alpha: the weight of Q (scaled by its own mean size) against cloning the
    buffer's actions in pi's loss (Fujimoto & Gu 2021's 2.5). Smaller keeps pi nearer the data."""
    prior_trajectories: int = Field(default=0, ge=0)
    """Candidates per planning round proposed by a policy cloned from the warm start's demos,
    each its rollout through the model for `horizon` steps (MoDem, Hansen et al. 2022; TD-MPC's
    policy-guided trajectories; agents/prior.py). They join every round's candidates, and (with
    `search_from_prior`) the search starts from the first (noise-free) one instead of the
    previous plan: `init_std` is then the trust region around what the demos do (mpc.py's doc).
    0: no prior. Needs a
    `warm_start`, or `value_policy` (whose learnt policy then proposes)."""
    search_from_prior: bool = True
    """With `prior_trajectories`: CEM and MPPI start each step from the first (noise-free)
    proposal instead of the previous plan shifted by one step (LOOP's actor-guided search). Why
    true: a prior cloned from good demos is a trust region the search must not leave (on
    pick-place: 8 of 8 held-out goals from the prior, 0 of 8 with its proposals but the search
    from the previous plan). false: the proposals only join the candidates, as in TD-MPC, whose
    policy learns from the start and is poor early."""
    prior_std: float = Field(default=0.1, ge=0.0)
    """Gaussian noise on each action of the proposals after the first (which is the policy's own,
    noise-free): the search's variations around what the demos did."""
    device: str = Field(default="cpu", pattern=r"^(cpu|cuda(:[0-9]+)?)$")
    """Where the model, the value and the planner run: `cpu`, or `cuda` / `cuda:N` for an NVIDIA
    GPU (the transition buffer stays in host memory; each fit moves it over once). Planning is
    ~20 small forward passes in a row per step, bound by kernel launches on a GPU: measured on an
    H200, 4x the training speed at the shipped sizes, the same call time for 32 envs as for 4,
    and PETS's own search 250x faster than on 2 CPU threads (benchmarks/mpc_speed.py). A run
    trained on a GPU is evaluated on the CPU where none is present."""

    @model_validator(mode="after")
    def _consistent(self) -> MPCSpec:
        if self.terminal_value and self.discount >= 1.0:
            raise ValueError("'terminal_value' needs 'discount' < 1 (e.g. 0.99): a value sums the rewards it discounts")
        for field, shapes in _SHAPES_THE_VALUE.items():
            value = getattr(self, field)
            if value != type(self).model_fields[field].default and not self.terminal_value:
                raise ValueError(f"'{field}' ({value}) {shapes}: it needs 'terminal_value: true'")
        if self.value_policy and (self.value_ensemble > 1 or self.value_pessimism):
            raise ValueError(f"'value_policy' has one Q of one policy: expected 'value_ensemble' 1 and 'value_pessimism' 0 "
                             f"(got {self.value_ensemble} and {self.value_pessimism:g})")
        if self.value_pessimism and self.value_ensemble < 2:
            raise ValueError(f"'value_pessimism' ({self.value_pessimism:g}) needs 'value_ensemble' >= 2: "
                             "it weighs the spread of the value heads")
        if self.elites > self.population:
            raise ValueError(f"'elites' ({self.elites}) must be <= 'population' ({self.population})")
        if self.optimism and self.particles < 2:
            raise ValueError(f"'optimism' ({self.optimism:g}) needs 'particles' >= 2: it weighs the spread of their returns")
        if self.particles % self.ensemble_size:
            raise ValueError(f"'particles' ({self.particles}) must be a multiple of 'ensemble_size' ({self.ensemble_size}): "
                             "each member carries as many particles")
        return self


class RuntimeSpec(StrictModel):
    vector: Literal["sharded", "ray", "async", "sync"] = "sharded"
    """`sharded`: the envs in `workers` slices, the last stepped by the main process and each
    other by a worker process (one round trip per worker per step); `ray`: the same slices, the
    others in Ray actors across a Ray cluster (optional extra `taskforge[ray]`); `async`: one
    process per env (gymnasium AsyncVectorEnv); `sync`: all in-process."""
    workers: int | None = Field(default=None, ge=1, le=1024)
    """Slices of envs for `sharded` and `ray` (`workers - 1` worker processes or actors plus the
    main process); default one per CPU core (of the Ray cluster, for `ray`)."""
    ray_address: str | None = None
    """`vector: ray`: the cluster to join (`ray.init(address=...)`, e.g. `ray://head:10001` or
    `auto`); default the `RAY_ADDRESS` environment variable, else a local Ray instance."""
    ray_max_restarts: int = Field(default=3, ge=0, le=1000)
    """`vector: ray`: how often each actor may be restarted after its process or node died; its
    envs are re-created and the run goes on (an event in events.jsonl)."""
    torch_threads: int = Field(default=1, ge=1, le=256)
    """Torch threads while collecting: one, so the env workers keep the other cores."""
    update_threads: int | None = Field(default=None, ge=1, le=256)
    """Torch threads during the PPO update; default every core (the workers wait meanwhile)."""

    @model_validator(mode="after")
    def _ray_fields_need_ray(self) -> RuntimeSpec:
        if self.vector != "ray" and self.ray_address is not None:
            raise ValueError(f"ray_address is only read with vector: ray (got vector: {self.vector})")
        if self.vector == "ray" and importlib.util.find_spec("ray") is None:
            raise ValueError("vector: ray needs Ray, an optional extra: pip install 'taskforge[ray]'")
        return self


class AgentSpec(StrictModel):
    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_\-.]+$")
    algo: Literal["ppo", "rl2", "mpc"] = "ppo"
    """`ppo`: one episode at a time; `rl2`: PPO over trials of `rl2.trial_episodes` episodes, with
    the previous action, reward and an episode-start flag added to the observation; `mpc`: a
    learned dynamics model and a planner (the `mpc` section)."""
    policy: PolicySpec = PolicySpec()
    asymmetric_critic: bool = False
    """The critic also sees privileged features (object velocity, goal, drawn physics)."""
    ppo: PPOSpec = PPOSpec()
    rl2: RL2Spec | None = None
    """Trial settings; required with `algo: rl2`, not allowed otherwise."""
    mpc: MPCSpec | None = None
    """Model and planner settings; read with `algo: mpc` (default `MPCSpec()`), not allowed otherwise."""
    runtime: RuntimeSpec = RuntimeSpec()

    @property
    def trial_episodes(self) -> int:
        """Episodes per trial: K for RL², 1 for a memoryless PPO agent."""
        return self.rl2.trial_episodes if self.rl2 is not None else 1

    @model_validator(mode="after")
    def _consistent(self) -> AgentSpec:
        ppo = self.ppo
        if self.policy.type != "mlp" and ppo.num_minibatches > ppo.num_sequences:
            raise ValueError(
                f"a recurrent policy trains on whole sequences (num_envs * rollout_steps / bptt_length = "
                f"{ppo.num_sequences}), so ppo.num_minibatches ({ppo.num_minibatches}) must be <= {ppo.num_sequences}"
            )
        if self.algo == "rl2":
            if self.rl2 is None:
                raise ValueError("algo 'rl2' needs an 'rl2' section (e.g. rl2: {trial_episodes: 10})")
            if self.policy.type == "mlp":
                raise ValueError("algo 'rl2' needs a recurrent policy (policy.type 'gru' or 'lstm'), not 'mlp'")
        elif self.rl2 is not None:
            raise ValueError("an 'rl2' section needs algo: rl2")
        if self.mpc is not None and self.algo != "mpc":
            raise ValueError("an 'mpc' section needs algo: mpc")
        if self.algo == "mpc" and self.policy.type != "mlp":
            raise ValueError("algo 'mpc' plans from the current observation: policy.type must be 'mlp' (the policy section is not used)")
        return self

    @property
    def planning(self) -> MPCSpec:
        """The `mpc` section, or its defaults."""
        return self.mpc or MPCSpec()

    def with_planning(self, **fields: Any) -> AgentSpec:
        """A copy whose `mpc` section has `fields` changed (`device="cpu"` to evaluate a GPU run
        on a CPU, a bigger search to time it); the values are not validated again."""
        return self.model_copy(update={"mpc": self.planning.model_copy(update=fields)})
