"""The learned ATC's network, below every controller: the graph models (a shared GCN actor, a
centralised critic), the masked categorical distribution for rsl-rl-lib, the feature schema
and the padding of observations of several vertiports to one size. The controller that plays a
checkpoint is :mod:`agents.controllers.gcn`; its training lives in :mod:`agents.training`."""
