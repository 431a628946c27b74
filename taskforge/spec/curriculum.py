"""Schema of a curriculum file: which agent, which (task, stages) in order, and the rules that
move the agent along them."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from taskforge.spec.common import StrictModel

SEED_PLACEHOLDER = "{seed}"


def init_for_seed(init_from: str, seed: int) -> str:
    """`init_from` for the run of `seed`: its `{seed}` replaced (a path without one is returned as is)."""
    return init_from.replace(SEED_PLACEHOLDER, str(seed))


class PromotionSpec(StrictModel):
    """Promote when success over the last `window` episodes of the current stage is at least
    `threshold` and the stage has run for `min_steps` env steps; or, when `max_steps` is set, once
    the stage has spent that many env steps without passing (a plateau must not hold the run)."""

    threshold: float = Field(default=0.8, ge=0.0, le=1.0)
    window: int = Field(default=100, ge=1)
    min_steps: int = Field(default=0, ge=0)
    """A floor on the steps spent in a stage before it may pass; 0 (the default) promotes as soon
    as the window shows the threshold, so a warm-started policy that already passes moves on."""
    max_steps: int | None = Field(default=None, ge=1)
    """The stage's step budget: after this many env steps in it the curriculum moves on anyway
    (event `promote` with reason `budget`); default none (wait for the threshold)."""

    @model_validator(mode="after")
    def _budget_above_floor(self) -> PromotionSpec:
        if self.max_steps is not None and self.max_steps < self.min_steps:
            raise ValueError(f"'max_steps' ({self.max_steps}) must be >= 'min_steps' ({self.min_steps})")
        return self


class DemotionSpec(StrictModel):
    """Go back one stage when success collapses below `threshold` over `window` episodes."""

    enabled: bool = False
    threshold: float = Field(default=0.1, ge=0.0, le=1.0)
    window: int = Field(default=100, ge=1)


class ReplaySpec(StrictModel):
    """Fraction of episodes spent on already-passed stages, so skills are not forgotten."""

    fraction: float = Field(default=0.1, ge=0.0, lt=1.0)


class SamplingSpec(StrictModel):
    """How sub-tasks of a task set (e.g. MT10) are chosen for each episode."""

    mode: Literal["uniform", "learning_progress"] = "uniform"
    reweight: float | None = Field(default=None, gt=0.0, le=0.5)
    """`learning_progress` only: Kanitscheider et al.'s p_θ, which stretches success near 0 before
    the fast and slow averages are differenced, so sub-tasks whose success is low and rising get
    the episodes (0.1 in the paper); null = plain |fast − slow|."""

    @model_validator(mode="after")
    def _reweight_needs_progress(self) -> SamplingSpec:
        if self.reweight is not None and self.mode != "learning_progress":
            raise ValueError(f"'reweight' applies to mode 'learning_progress' only (mode is '{self.mode}')")
        return self


class EvaluationSpec(StrictModel):
    """Periodic deterministic evaluation during training (logged as `eval_*`)."""

    every_steps: int = Field(default=100_000, ge=1)
    episodes: int = Field(default=20, ge=1)
    split: Literal["train", "test"] = "test"
    stage: str | None = None
    """Evaluate this stage of the current phase (e.g. the final `place`, to compare a curriculum
    with flat training); default: whichever stage the curriculum is on."""
    tasks: Literal["current", "all"] = "current"
    """`current`: the current phase's task (a task set's sub-tasks drawn at random). `all`: every
    phase's task and, for a task set (MT10), each sub-task on its own, `episodes` each; logged per
    task (`eval/<task>`) and as their mean (`eval_success_rate`). For one policy across MT10 or
    across robot variants: the number that says it still does every task, not just the newest."""
    stop_on_success: bool = False
    """End each evaluation episode when the stage first succeeds. Success counts if it held at
    any step, so the success rate is unchanged and a good policy is evaluated several times
    faster; returns and lengths then cover the steps up to success only."""


class CheckpointSpec(StrictModel):
    every_steps: int = Field(default=50_000, ge=1)


class PhaseSpec(StrictModel):
    """One entry of the curriculum: a task file and the stages of it to run, in order."""

    task: str
    """Path to a task file, relative to the curriculum file."""
    stages: list[str] = Field(default_factory=list)
    """Stages in order; empty = every stage of the task, in file order."""

    @field_validator("stages")
    @classmethod
    def _unique(cls, stages: list[str]) -> list[str]:
        dupes = sorted({s for s in stages if stages.count(s) > 1})
        if dupes:
            raise ValueError(f"a stage may appear once per phase; repeated: {', '.join(dupes)}")
        return stages
    promotion: PromotionSpec | None = None
    """Overrides the curriculum-wide promotion rule for this phase."""
    sampling: SamplingSpec | None = None


class RegularizerSpec(StrictModel):
    """DAPG-style behaviour-cloning term added to PPO's loss: `weight * decay**k` times the
    negative log-likelihood of demo actions, at PPO update k."""

    weight: float = Field(default=0.1, ge=0.0)
    """Weight at the first PPO update; 0 turns the term off."""
    decay: float = Field(default=0.95, gt=0.0, le=1.0)
    """Multiplies the weight after every PPO update (DAPG's 0.95: 1 % of the weight after 90)."""


class DaggerSpec(StrictModel):
    """DAgger after the demos: roll out the pretrained student, label the states it visits with
    the scripted policy's action, aggregate, refit (`taskforge/training/dagger.py`)."""

    rounds: int = Field(default=0, ge=0)
    """Rounds of student rollouts after the recorded demos; 0 = behaviour cloning only."""
    steps_per_round: int = Field(default=10_000, ge=1)
    """Env steps the student runs per round (all envs together); they count in the run's budget."""
    epochs: int = Field(default=20, ge=1)
    """Passes over the aggregate at each refit (warm-started from the previous fit)."""


class FineTuneSpec(StrictModel):
    """How PPO starts from the pretrained policy, so that it does not undo it."""

    exploration_std: Literal["auto", "preset"] | float = "auto"
    """`auto`: per action dimension, `std_scale` times the pretrained policy's RMS error on the
    expert's actions, clipped to [`std_min`, `std_max`]; `preset`: the agent's `init_log_std`;
    a number: that std for every dimension."""
    std_scale: float = Field(default=1.0, gt=0.0)
    std_min: float = Field(default=0.05, gt=0.0)
    std_max: float = Field(default=1.0, gt=0.0)
    critic_warmup_steps: int = Field(default=0, ge=0)
    """Env steps of PPO updates that train only the critic before the actor moves."""
    freeze_observation_statistics: bool = True
    """Keep the observation normaliser at the statistics the policy was pretrained with; PPO's
    rollouts would otherwise shift them and with them the pretrained behaviour."""

    @model_validator(mode="after")
    def _std_range(self) -> FineTuneSpec:
        if self.std_min > self.std_max:
            raise ValueError(f"'std_min' ({self.std_min}) must be <= 'std_max' ({self.std_max})")
        if isinstance(self.exploration_std, float) and self.exploration_std <= 0:
            raise ValueError(f"'exploration_std' must be 'auto', 'preset' or a positive number (got {self.exploration_std})")
        return self


class WarmStartSpec(StrictModel):
    """Pretrain the agent on demonstrations before the curriculum starts, then keep a decaying
    BC term in PPO's loss (MLP, LSTM or GRU policies; not RL²)."""

    demos: str | None = None
    """A demos file (`taskforge demos`), relative to the curriculum file."""
    generate_episodes: int | None = Field(default=None, ge=1)
    """Or: record this many scripted episodes at the start of training (train goals; failed
    episodes are dropped). Exactly one of `demos` and `generate_episodes`."""
    phase: int | Literal["all"] = Field(default=0)
    """Which phase's task the demos and DAgger's rollouts come from (index into `phases`), or
    `all`: every phase's task (`generate_episodes` split evenly over them, DAgger's envs spread
    over them), for one policy across robot variants or task sets."""
    stage: str | None = None
    """Which stage of that task; default the phase's last stage. With `phase: all` it must exist
    in every phase. With `demos`, checked against the stage the file was recorded on."""

    @field_validator("phase", mode="before")
    @classmethod
    def _phase_index(cls, phase: object) -> object:
        """One clear line for a bad value (the union's own errors would give one per member)."""
        if phase == "all" or (isinstance(phase, int) and not isinstance(phase, bool) and phase >= 0):
            return phase
        raise ValueError(f"expected a phase index counting from 0, or 'all'; got {phase!r}")
    bc_epochs: int = Field(default=50, ge=0)
    bc_batch_size: int = Field(default=256, ge=1)
    bc_learning_rate: float = Field(default=1e-3, gt=0.0)
    regularizer: RegularizerSpec = RegularizerSpec()
    dagger: DaggerSpec = DaggerSpec()
    fine_tune: FineTuneSpec = FineTuneSpec()

    @model_validator(mode="after")
    def _one_source(self) -> WarmStartSpec:
        if (self.demos is None) == (self.generate_episodes is None):
            raise ValueError("give exactly one of 'demos' (a file) and 'generate_episodes' (a number)")
        return self


class CurriculumSpec(StrictModel):
    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_\-.]+$")
    """Also names the default run directory (runs/<name>-seed<seed>)."""
    agent: str
    """Path to an agent preset, relative to the curriculum file."""
    seed: int = 0
    total_steps: int = Field(ge=1)
    phases: list[PhaseSpec] = Field(min_length=1)
    promotion: PromotionSpec = PromotionSpec()
    demotion: DemotionSpec = DemotionSpec()
    replay: ReplaySpec = ReplaySpec()
    sampling: SamplingSpec = SamplingSpec()
    evaluation: EvaluationSpec = EvaluationSpec()
    checkpoint: CheckpointSpec = CheckpointSpec()
    warm_start: WarmStartSpec | None = None
    """Behaviour-cloning warm start from demonstrations; none by default."""
    init_from: str | None = None
    """A run directory (its final policy, else its latest checkpoint) or checkpoint file, relative
    to this file, whose learnt weights the run starts from: the networks and the statistics they
    were trained on (and an MPC agent's data); the optimizer, step count, learning-rate schedule
    and curriculum start fresh. Why: to carry what one curriculum taught into another (a search
    learnt on one plane of a box into the whole box, a policy into a new robot variant) without
    learning it again. The agent preset must build the same networks. Read only when a run
    starts, not on `--resume`. `{seed}` in it becomes the run's seed (`init_for_seed`), so each
    seed of a multi-seed fine-tune starts from its own source run, not all from one."""

    @field_validator("init_from")
    @classmethod
    def _only_the_seed_placeholder(cls, init_from: str | None) -> str | None:
        rest = "" if init_from is None else init_from.replace(SEED_PLACEHOLDER, "")
        if "{" in rest or "}" in rest:
            raise ValueError(f"the only placeholder init_from may hold is {SEED_PLACEHOLDER} (the run's seed); got {init_from!r}")
        return init_from
