"""The rsl_rl vector envs: the learner's reward, and the parity of the multi-agent and
single-agent paths."""


import pytest
import torch

from agents.gcn.models import GraphActor
from agents.gcn.features import feature_names
from agents.training.runner import runner_config
from agents.gcn.features import POLICY_GROUPS
from agents.training.vec_env import MultiAgentVecEnv, SingleAgentVecEnv
from marl_vertiport.config import load_config

torch.set_num_threads(1)


# ------------------------------------------------------------------ distribution
from helpers import tiny_config


def test_lost_vehicle_penalty_by_hand():
    """The learner's reward is the paper's reward less the penalty per vehicle lost in the
    step: evtol_2 at 0 % on a normal port is stranded in the first step."""
    cfg = load_config("paper", **{"atc.energy_check": False})
    rewards = []
    for penalty in (0.0, 40.0):
        env = MultiAgentVecEnv(cfg, num_envs=1, seed=0, lost_vehicle_penalty=penalty)
        sim = env.envs[0].sim
        on_port = [v for v in range(sim.n) if sim.status[v] == 0]
        sim.battery[on_port[-1]] = 0.0
        acting = int(env.acting_rows()[0])
        actions = torch.zeros(env.num_envs, 1)  # stay
        _, r, _, _ = env.step(actions)
        paper = env.envs[0].rewards[env.envs[0].possible_agents[acting]]
        assert int(sim.lost.sum()) == 1
        rewards.append((float(r[0]), paper))
        env.close()
    (r0, paper0), (r1, paper1) = rewards
    assert r0 == pytest.approx(paper0) and paper1 == pytest.approx(paper0)
    assert r1 == pytest.approx(paper0 - 40.0)

@pytest.mark.slow
def test_actor_probabilities_identical_through_aec_and_single_agent_paths():
    torch.manual_seed(0)
    ma = MultiAgentVecEnv("paper_uncertain", num_envs=1, seed=3)
    sa = SingleAgentVecEnv("paper_uncertain", num_envs=1, seed=3)
    obs_ma, obs_sa = ma.get_observations(), sa.get_observations()
    actor = GraphActor(obs_ma, {"actor": list(POLICY_GROUPS)}, "actor", 1, feature_names("observation"))
    actor.eval()
    for step in range(1440):
        row = int(ma.acting_rows()[0])
        with torch.no_grad():
            p_ma = actor.action_probabilities(obs_ma[row:row + 1])
            p_sa = actor.action_probabilities(obs_sa)
        assert torch.equal(p_ma, p_sa), f"probabilities differ at step {step}"
        action = torch.multinomial(p_sa, 1).float()
        rows = torch.zeros(ma.num_envs, 1)
        rows[row] = action
        obs_ma, r_ma, d_ma, _ = ma.step(rows)
        obs_sa, r_sa, d_sa, _ = sa.step(action)
        assert float(r_ma[row]) == float(r_sa[0])
    assert bool(d_sa[0]) and bool(d_ma.all())

def test_one_ppo_iteration_same_update_in_both_modes_on_the_same_observations():
    """With one eVTOL the multi-agent rows are the single-agent rows; fed the same observations
    (the critic on the same groups), one PPO iteration from the same seed updates the
    parameters identically."""
    from rsl_rl.runners import OnPolicyRunner

    params = []
    for mode, cls in (("multi_agent", MultiAgentVecEnv), ("single_agent", SingleAgentVecEnv)):
        cfg = tiny_config(mode, env_config="paper")
        env = cls(build_env_cfg(), num_envs=2, seed=5)
        rc = runner_config(cfg)
        rc["obs_groups"]["critic"] = list(POLICY_GROUPS)
        rc["critic"]["feature_names"] = feature_names("observation")
        torch.manual_seed(0)
        runner = OnPolicyRunner(env, rc, log_dir=None, device="cpu")
        runner.learn(1)
        params.append(torch.cat([p.detach().flatten() for p in runner.alg.actor.parameters()]
                                + [p.detach().flatten() for p in runner.alg.critic.parameters()]))
        env.close()
    assert torch.equal(params[0], params[1])

def build_env_cfg():
    return load_config("paper", fleet_size=1)
