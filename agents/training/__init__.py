"""Training the learned ATC (``python -m agents.train``): rsl_rl vector envs over the AEC and
Gymnasium APIs (``vec_env``), the imitation warm start (``imitation``), and the pipeline that
runs warm start, PPO and the final evaluation from a train config (``pipeline``)."""
