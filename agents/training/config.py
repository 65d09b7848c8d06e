"""The train config's schema (``configs/train/*.yaml``): every key with its default, and the
checks that name a bad one (docs/training.md, "Train configs")."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from agents.common.names import RENAMED_TEACHERS, note_renamed, upgrade_agents
from agents.controllers.gcn import GRAPH_ACTOR
from agents.training.fit_selection import KEEP_RULES
from agents.training.teachers import TEACHERS
from agents.training.vec_env import CRITIC_INPUTS, ROW_LAYOUTS
from marl_vertiport.config import (
    LATEST_RULES, RULES_VERSIONS, ConfigError, load_config, load_yaml_dataclass, with_rules,
)

TRAIN_CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "train"


@dataclass(frozen=True)
class PretrainConfig:
    """Warm start of the actor by imitation (agents/training/imitation.py)."""

    days: int = 0
    """Days of demonstrations per round (0: no warm start)."""
    day_steps: int = 1440
    """Steps of each demonstration day (a full day: 1440)."""
    starts: int = 0
    """Extra episodes per round that cover only the start of a day."""
    start_steps: int = 120
    """Steps of each of those episodes."""
    teacher: str = "planner"
    """``planner`` (the look-ahead planner), ``guarded_planner`` (the planner behind the guard),
    ``search`` (the wide look-ahead search, with the config's uncertainties), ``lookahead`` (the
    learned ATC's look-ahead around the actor being fit: expert iteration) or ``dispatcher``
    (the expert dispatcher): :mod:`agents.training.teachers`."""
    planner_horizon: int = 40
    """Steps the planner simulates per candidate action."""
    planner_margin: float = 3.0
    """Reward by which the planner's best action must beat the dispatcher's to be the label
    (near-ties keep the dispatcher's choice, which is easier to learn)."""
    planner_expect_failures: bool = False
    """The planner values a take-off in expectation over its failure (``expect_failures`` of
    :class:`~agents.controllers.planner.PlannerController`; configs with take-off failures)."""
    planner_rescue: bool = False
    """The planner simulates the actions its candidates leave out where every candidate loses a
    vehicle (``rescue`` of :class:`~agents.controllers.planner.PlannerController`)."""
    workers: int = 2
    """Processes that run demonstration days."""
    epochs: int = 6
    """Passes over the demonstrations after each round."""
    regret_cap: float = 0.0
    """Weights of the imitation loss: 1 + the teacher's value spread over the candidates,
    capped at this (0: every decision weighs 1); see ``imitation.label_weights``."""
    batch_size: int = 1024
    learning_rate: float = 1e-3
    dagger_rounds: int = 0
    """Rounds of DAgger after behaviour cloning: the actor drives, the teacher labels."""
    dagger_epochs: int = 0
    """Passes over all the decisions so far after each DAgger round, the fit going on from the
    last one's weights (0: ``epochs``); fewer than ``epochs`` keep the rounds' fits, which grow
    with the data, within the run's time."""
    noise: float = 0.0
    """Probability that the driver's action at a step with a choice of a day start is replaced
    by a uniformly drawn legal action (the label stays the teacher's): the data then covers the
    states just off the driver's path, from which it must recover (noise injection, as in
    DART). The full days, which also score the fits, run without it."""
    low_battery_starts: int = 0
    """Extra day starts per round in which every battery begins low, cycling through
    ``low_battery_pct``: the teacher shows what to do when a charge cannot be had for all."""
    low_battery_pct: tuple[float, ...] = (10.0, 20.0, 30.0, 45.0)
    """Initial battery levels (%) of those starts."""
    keep: str = "round"
    """Which fit the warm start keeps (with DAgger rounds): ``round``, the best by the mean
    score of the full days it drove in the round after its fit (each fit on days of its own);
    ``paired``, the best by its score on the last round's full days, which every fit drives
    (the same days for all: more days driven, a fairer comparison); ``last``, the last fit."""
    rule_weight: float = 0.0
    """The dispatcher as the actor's prior (:mod:`agents.controllers.prior`): the actor drives,
    proposes to a ``lookahead`` teacher and is fit as ``log pi(a) + rule_weight * [a is the
    dispatcher's choice]``, so it learns where to depart from the rule rather than the rule
    itself; play the result as ``prior[policy=<checkpoint>]`` (which reads this weight from
    it). 0: the actor alone. PPO does not train such an actor: every PPO iteration must be a
    critic warm-up."""
    propose_with_prior: bool = True
    """With ``rule_weight`` > 0 and the ``lookahead`` teacher: whether the actor proposes to
    the teacher with the dispatcher as its prior (as it drives), or alone (``False``): then the
    look-ahead judges every departure the actor would make without the rule, not only those it
    is ``rule_weight`` nats surer of, and the labels show which of them pay."""

    @property
    def runs(self) -> bool:
        """Whether the warm start runs (``days`` and ``epochs`` > 0)."""
        return self.days > 0 and self.epochs > 0

    @classmethod
    def upgrade_data(cls, data: dict) -> dict:
        """Keys and teachers named as before 0.2.0 (``rollout_horizon``, ``teacher: rollout``)
        read as their names now, with a note."""
        for old in [k for k in data if isinstance(k, str) and k.startswith("rollout_")]:
            new = "planner_" + old[len("rollout_"):]
            if new in data:
                raise ConfigError(f"pretrain.{old}: the old name of pretrain.{new}; give one")
            note_renamed(f"pretrain.{old}", f"pretrain.{new}", "train-config key")
            data[new] = data.pop(old)
        teacher = data.get("teacher")
        if isinstance(teacher, str) and teacher in RENAMED_TEACHERS:
            note_renamed(teacher, RENAMED_TEACHERS[teacher], "pretrain.teacher")
            data["teacher"] = RENAMED_TEACHERS[teacher]
        return data


@dataclass(frozen=True)
class AlgorithmConfig:
    """rsl_rl PPO arguments (same names)."""

    class_name: str = "agents.training.ppo:WarmupPPO"
    """The algorithm rsl_rl builds (``module:Class``): rsl_rl's ``PPO`` with a critic warm-up
    and a linear learning-rate schedule (agents/training/ppo.py)."""
    learning_rate: float = 1e-4
    gamma: float = 0.99
    lam: float = 0.95
    entropy_coef: float = 0.001
    clip_param: float = 0.1
    num_learning_epochs: int = 4
    num_mini_batches: int = 4
    value_loss_coef: float = 1.0
    max_grad_norm: float = 1.0
    schedule: str = "adaptive"
    """``adaptive`` (rsl_rl: the rate follows the KL divergence toward ``desired_kl``),
    ``fixed``, or ``linear`` (decays linearly to 0 over the run's iterations)."""
    desired_kl: float = 0.01
    use_clipped_value_loss: bool = True
    """rsl_rl's value clipping: a value may move at most ``clip_param`` (in reward units) from
    its rollout estimate in an update; with returns of hundreds it all but stops the critic."""
    normalize_advantage_per_mini_batch: bool = False


@dataclass(frozen=True)
class ModelConfig:
    """The networks rsl_rl builds, named as ``module:Class`` (rsl_rl's ``class_name``), and
    their sizes."""

    actor_class: str = GRAPH_ACTOR
    """The shared actor: an rsl_rl ``MLPModel`` that reads the three observation groups. The GCN
    controller plays checkpoints of ``GraphActor`` only (it never imports a class a file names)."""
    critic_class: str = "agents.gcn.models:GraphCritic"
    """The critic (the centralised one reads ``state()``'s groups)."""
    distribution_class: str = "agents.gcn.distribution:MaskedCategorical"
    """The actor's output distribution (legal actions only)."""
    hidden: int = 64
    """Width of the GCN layers."""
    hidden_dims: tuple[int, ...] = (128, 64)
    """MLP head (the paper: 128-64)."""


@dataclass(frozen=True)
class EvaluationConfig:
    episodes: int = 20
    """Held-out episodes per case for the evaluation at the end of training (0: none)."""
    agents: tuple[str, ...] = ("random", "fcfs", "dispatcher")
    """Baselines evaluated beside the learned policy."""

    #: Agents named as before 0.2.0 read as their names now, with a note.
    upgrade_data = classmethod(upgrade_agents)


@dataclass(frozen=True)
class EnsembleConfig:
    """Distillation of an ensemble of imitation fits after the warm start
    (agents/training/ensemble.py)."""

    fits: int = 0
    """Refits of the warm start's demonstrations from fresh weights; with the warm start they
    form the ensemble (0: no ensemble stage)."""
    days: int = 10
    """Full training days the ensemble drives; their states join the demonstrations."""
    epochs: int = 8
    """Passes of the distillation over those states and the demonstrations."""
    batch_size: int = 256
    learning_rate: float = 3e-4


@dataclass(frozen=True)
class TrainConfig:
    mode: str = "multi_agent"
    """``multi_agent`` (AEC, one row per eVTOL, critic on ``state()``) or ``single_agent``."""
    env_config: str = "paper"
    """The env config of the run (the end-of-training evaluation's first case)."""
    scenarios: tuple[str, ...] = ()
    """Env configs to train across (multi-agent mode): PPO's copies and the warm start's days
    cycle through them. Empty: ``env_config`` alone."""
    rules: int = LATEST_RULES
    """The env's rules version every env of the run plays under (``vertiport_v{rules}``: 1 the
    separation check, 0 the rules before it)."""
    lost_vehicle_penalty: float = 0.0
    """Subtracted from the reward the learner sees for each vehicle lost in a step (stranded
    in the air or on the ground); the warm start scores its fits the same way. Evaluation
    reports the paper's reward. 0: the paper's reward."""
    num_envs: int = 32
    num_steps_per_env: int = 32
    iterations: int = 250
    save_interval: int = 10
    seed: int = 0
    device: str = "cpu"
    """``cpu`` or ``cuda`` / ``cuda:0`` where a GPU is present."""
    torch_threads: int = 1
    """Intra-op threads; tiny graph batches run fastest on one."""
    team_reward: bool = True
    """Multi-agent mode: every eVTOL's row gets the step's reward (cooperative); False credits
    only the acting eVTOL (per-agent returns, which reward selfish use of the charger)."""
    rows: str = "agents"
    """Multi-agent mode: ``agents`` (a row per env copy and eVTOL; the rows whose eVTOL has no
    turn only "stay") or ``turns`` (a row per copy: the eVTOL whose turn it is); see
    agents/training/vec_env.py."""
    critic: str = "state"
    """Multi-agent mode: ``state`` (the centralised critic reads ``state()``) or
    ``observation`` (each eVTOL's critic reads its own observation, shared weights). The
    single-agent mode's critic always reads the observation."""
    conflict_penalty: float = 0.0
    """Subtracted from the reward the learner sees in a step whose acting eVTOL was in a
    predicted conflict and did not avoid it (the paper's S = -5, counted as a collision);
    evaluation reports the paper's reward. 0: none."""
    reward_scale: float = 1.0
    """The learner's reward (after the penalties) is multiplied by this; metrics and
    evaluation keep the paper's reward."""
    critic_warmup_iterations: int = 0
    """First PPO iterations with the actor frozen, so that the critic fits the warm-started
    policy before its advantages move the actor."""
    warm_start_temperature: float = 1.0
    """Before PPO, the warm-started actor's logits are divided by this for good (its output
    layers scaled, see :meth:`GraphActor.sharpen`): below 1 the policy PPO samples, and so
    improves, comes closer to the greedy policy that is deployed. The greedy actions stay
    those of the warm start. 1: as imitated."""
    init_checkpoint: str = ""
    """A checkpoint (``model_<it>.pt`` of a run, or a shipped one) whose actor and critic
    weights the run starts from: tensors only are read, and neither its optimizer state nor its
    iteration. Its model must be this config's ``model``. Without a warm start
    (``pretrain.days: 0``) PPO starts from it; with one, the warm start goes on from it: its
    actor drives the first round and the teacher labels (DAgger from the start; with
    ``pretrain.teacher: lookahead``, expert iteration from this policy). Empty: the warm start
    (or nothing) as ``pretrain`` and ``ensemble`` say."""
    pretrain: PretrainConfig = field(default_factory=PretrainConfig)
    ensemble: EnsembleConfig = field(default_factory=EnsembleConfig)
    algorithm: AlgorithmConfig = field(default_factory=AlgorithmConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    evaluation: EvaluationConfig = field(default_factory=EvaluationConfig)

    def __post_init__(self) -> None:
        checks = [
            (self.mode in ("multi_agent", "single_agent"), "mode", "multi_agent or single_agent"),
            (self.rules in RULES_VERSIONS, "rules", f"one of {list(RULES_VERSIONS)}"),
            (self.num_envs >= 1, "num_envs", "must be >= 1"),
            (self.num_steps_per_env >= 1, "num_steps_per_env", "must be >= 1"),
            (self.iterations >= 1, "iterations", "must be >= 1"),
            (self.save_interval >= 1, "save_interval", "must be >= 1"),
            (self.torch_threads >= 1, "torch_threads", "must be >= 1"),
            (self.algorithm.learning_rate > 0, "algorithm.learning_rate", "must be > 0"),
            (0 <= self.algorithm.gamma <= 1, "algorithm.gamma", "must lie in [0, 1]"),
            (self.algorithm.schedule in ("adaptive", "fixed", "linear"), "algorithm.schedule",
             "adaptive, fixed or linear"),
            (self.rows in ROW_LAYOUTS, "rows", " or ".join(ROW_LAYOUTS)),
            (self.critic in CRITIC_INPUTS, "critic", " or ".join(CRITIC_INPUTS)),
            (self.rows == "agents" or self.team_reward, "rows",
             "turns holds one stream of turns per copy: it needs team_reward: true"),
            (self.reward_scale > 0 and math.isfinite(self.reward_scale), "reward_scale",
             "must be a finite number > 0"),
            (self.conflict_penalty >= 0, "conflict_penalty", "must be >= 0"),
            (self.warm_start_temperature > 0 and math.isfinite(self.warm_start_temperature),
             "warm_start_temperature", "must be a finite number > 0"),
            (self.warm_start_temperature == 1.0 or bool(self.init_checkpoint)
             or self.pretrain.runs, "warm_start_temperature",
             "sharpens the warm start: it needs pretrain.days and pretrain.epochs > 0, or an "
             "init_checkpoint"),
            (not self.init_checkpoint or self.ensemble.fits == 0,
             "init_checkpoint", "cannot start an ensemble's warm start: it needs ensemble.fits: 0"),
            (self.ensemble.fits >= 0, "ensemble.fits", "must be >= 0"),
            (self.ensemble.fits == 0 or self.pretrain.runs,
             "ensemble.fits", "refits the warm start: it needs pretrain.days and pretrain.epochs > 0"),
            (self.ensemble.days >= 1 and self.ensemble.epochs >= 1 and self.ensemble.batch_size >= 1,
             "ensemble", "days, epochs and batch_size must be >= 1"),
            (self.ensemble.learning_rate > 0, "ensemble.learning_rate", "must be > 0"),
            (min(self.pretrain.days, self.pretrain.epochs, self.pretrain.dagger_rounds,
                 self.pretrain.dagger_epochs) >= 0,
             "pretrain", "days, epochs, dagger_rounds and dagger_epochs must be >= 0"),
            (self.pretrain.day_steps >= 1, "pretrain.day_steps", "must be >= 1"),
            (self.pretrain.starts >= 0 and self.pretrain.start_steps >= 1, "pretrain.starts",
             "starts must be >= 0 and start_steps >= 1"),
            (self.pretrain.teacher in TEACHERS, "pretrain.teacher", f"one of {', '.join(TEACHERS)}"),
            (self.pretrain.planner_horizon >= 1, "pretrain.planner_horizon", "must be >= 1"),
            (self.pretrain.workers >= 1, "pretrain.workers", "must be >= 1"),
            (self.pretrain.regret_cap >= 0, "pretrain.regret_cap", "must be >= 0"),
            (self.pretrain.keep in KEEP_RULES, "pretrain.keep", f"one of {', '.join(KEEP_RULES)}"),
            (self.pretrain.days + self.pretrain.starts + self.pretrain.low_battery_starts <= 100,
             "pretrain", "days + starts + low_battery_starts must be <= 100 (seeds of a round)"),
            (0.0 <= self.pretrain.noise < 1.0, "pretrain.noise", "must lie in [0, 1)"),
            (self.pretrain.low_battery_starts >= 0, "pretrain.low_battery_starts", "must be >= 0"),
            (len(self.pretrain.low_battery_pct) > 0
             and all(0.0 < b <= 100.0 for b in self.pretrain.low_battery_pct),
             "pretrain.low_battery_pct", "a non-empty list of levels in (0, 100]"),
            (self.pretrain.rule_weight >= 0 and math.isfinite(self.pretrain.rule_weight),
             "pretrain.rule_weight", "must be a finite number of nats >= 0"),
            (self.pretrain.rule_weight == 0 or (self.pretrain.runs and self.ensemble.fits == 0),
             "pretrain.rule_weight", "weighs the warm start's actor against the dispatcher: it "
             "needs pretrain.days and pretrain.epochs > 0 and ensemble.fits: 0"),
            (self.pretrain.rule_weight == 0 or self.iterations <= self.critic_warmup_iterations,
             "pretrain.rule_weight", "PPO does not train an actor with the dispatcher as its "
             "prior: set critic_warmup_iterations >= iterations (the actor frozen)"),
            (self.pretrain.propose_with_prior
             or (self.pretrain.rule_weight > 0 and self.pretrain.teacher == "lookahead"),
             "pretrain.propose_with_prior", "false only with pretrain.rule_weight > 0 and "
             "pretrain.teacher: lookahead (without a prior the actor proposes alone anyway)"),
            (self.evaluation.episodes >= 0, "evaluation.episodes", "must be >= 0"),
            (self.lost_vehicle_penalty >= 0, "lost_vehicle_penalty", "must be >= 0"),
            (self.device == "cpu" or self.device.startswith("cuda"), "device", "cpu or cuda[:N]"),
        ]
        for ok, name, msg in checks:
            if not ok:
                raise ConfigError(f"{name}: {msg}")


#: Train configs of rules v0, moved in 0.2.0 from configs/train/ into the experiments that use
#: them: their old names still load (with a note).
MOVED_TRAIN_CONFIGS = {
    "paper": "experiments/paper-hyperparameters/configs/paper.yaml",
    "scratch_v0": "experiments/scratch-ppo-rules-v0/configs/scratch_v0.yaml",
    "scratch_independent": "experiments/centralised-critic-rules-v0/configs/scratch_independent.yaml",
    "scratch_single": "experiments/centralised-critic-rules-v0/configs/scratch_single.yaml",
    "factors/agent_rows": "experiments/scratch-ppo-factors-rules-v0/configs/agent_rows.yaml",
    "factors/unscaled_reward": "experiments/scratch-ppo-factors-rules-v0/configs/unscaled_reward.yaml",
    "factors/value_clipping": "experiments/scratch-ppo-factors-rules-v0/configs/value_clipping.yaml",
    "ensemble_v0": "experiments/ensemble-warm-start-rules-v0/configs/ensemble_v0.yaml",
    "single_fit": "experiments/ensemble-warm-start-rules-v0/configs/single_fit.yaml",
    "ppo_stage/sharpened": "experiments/ensemble-warm-start-rules-v0/configs/sharpened.yaml",
    "ppo_stage/sharpened_gamma999":
        "experiments/ensemble-warm-start-rules-v0/configs/sharpened_gamma999.yaml",
}


def train_config_path(config: str | Path) -> str | Path:
    """``config`` as ``load_train_config`` reads it: a name of :data:`MOVED_TRAIN_CONFIGS`
    becomes its file (with a note), anything else is left as it is."""
    name = str(config)
    if name in MOVED_TRAIN_CONFIGS and not (TRAIN_CONFIG_DIR / f"{name}.yaml").exists():
        moved = TRAIN_CONFIG_DIR.parents[1] / MOVED_TRAIN_CONFIGS[name]
        note_renamed(name, MOVED_TRAIN_CONFIGS[name], "train config")
        return moved
    return config


def load_train_config(config: str | Path) -> TrainConfig:
    """A name in ``configs/train/``, a YAML path, or the name of a config that moved into
    ``experiments/`` (:data:`MOVED_TRAIN_CONFIGS`)."""
    return load_yaml_dataclass(TrainConfig, train_config_path(config), TRAIN_CONFIG_DIR,
                               "train config")


def scenario_configs(cfg: TrainConfig) -> list:
    """The env configs a run trains on (``scenarios``, or ``env_config`` alone), loaded."""
    return [with_rules(load_config(name), cfg.rules)
            for name in (cfg.scenarios or (cfg.env_config,))]
