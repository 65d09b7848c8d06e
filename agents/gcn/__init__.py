"""The learned ATC: the graph models (a shared GCN actor, a centralised critic), the masked
categorical distribution for rsl-rl-lib, the feature schema, observation padding and the
inference controller (``policy``). Its training lives in :mod:`agents.gcn.train`."""
