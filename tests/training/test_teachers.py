"""The look-ahead teacher (pretrain.teacher: lookahead): the learned ATC's look-ahead around the
learner labels each decision with what it takes, weighted by its reward contest or as forced."""

from agents.controllers.dispatcher import DispatcherController
from agents.controllers.gcn import GCNController, read_checkpoint
from agents.controllers.search import LOSS_COST
from agents.training.teachers import LookaheadTeacher, make_teacher
from marl_vertiport import vertiport_v1
from marl_vertiport.sim.schema import HOVERING, ON_CHARGER, ON_PORT

SHIPPED = "agents/checkpoints/gcn_default.pt"


def test_the_lookahead_teacher_is_built_on_the_learner_or_the_dispatcher():
    learner = read_checkpoint(SHIPPED)
    teacher = make_teacher("lookahead", 40, 3.0, seed=3, learner=learner)
    assert isinstance(teacher, LookaheadTeacher) and isinstance(teacher.look.proposer, GCNController)
    assert isinstance(teacher.look.own_rollout_policy, DispatcherController)
    assert teacher.look.settings.seed == 3 and teacher.look.settings.samples == 4
    plain = make_teacher("lookahead", 40, 3.0, seed=3)
    assert isinstance(plain.look.proposer, DispatcherController)


def test_the_lookahead_teacher_weighs_contests_by_their_values_and_overrides_as_forced():
    """Over the first 6 hours of a day of case 2, each label is the look-ahead's decision; a
    decision with a reward contest carries both candidates' values (a vehicle lost worth
    LOSS_COST of reward) and is never forced; a decision that leaves the learner's choice
    without a contest is forced; one that keeps it without a contest weighs nothing extra."""
    teacher = make_teacher("lookahead", 40, 3.0, seed=11, learner=read_checkpoint(SHIPPED))
    env = vertiport_v1.env(config="paper_uncertain", **{"schedule.episode_steps": 360})
    env.reset(seed=1000)
    teacher.reset(seed=1000)
    sim = env.unwrapped.sim
    teacher.bind(sim)
    contests = kept = left = 0
    for agent in env.agent_iter():
        obs, _, term, trunc, _ = env.last()
        if term or trunc:
            env.step(None)
            continue
        choice = obs["action_mask"].sum() > 1 and sim.status[sim.acting] in (ON_PORT, ON_CHARGER, HOVERING)
        proposal = teacher.look.proposer.act(obs)
        label = teacher.act(obs)
        assert obs["action_mask"][label]
        contest = teacher.look.last_contest
        assert teacher.last_q == {a: v[1] - LOSS_COST * v[0] for a, v in contest.items()}
        if contest:
            contests += 1
            assert set(contest) == {proposal, label} or (proposal in contest and label == proposal)
            assert not teacher.last_forced
        elif choice:
            assert teacher.last_forced == (label != proposal)
            kept += label == proposal
            left += label != proposal
        env.step(label)
    env.close()
    teacher.close()
    assert contests > 0 and kept > 0 and left > 0


def test_each_days_teacher_receives_the_learner_that_drives_it(monkeypatch):
    """The teacher of a DAgger day is built on that day's learner (expert iteration: a better
    actor makes a better teacher); a day the teacher drives gives it none."""
    import agents.training.demonstrations as demonstrations
    from agents.training.demonstrations import DayTask, label_day
    from marl_vertiport.config import load_config, to_dict

    given = []
    original = demonstrations.make_teacher

    def recording(*args, **kwargs):
        given.append(kwargs.get("learner"))
        return original(*args, **kwargs)

    monkeypatch.setattr(demonstrations, "make_teacher", recording)
    learner = read_checkpoint(SHIPPED)
    env_cfg = to_dict(load_config("paper"))
    label_day(DayTask(env_cfg, 3, 20, "dispatcher", 4, learner=learner))
    label_day(DayTask(env_cfg, 3, 20, "dispatcher", 4))
    assert given[0] is learner and given[1] is None
