"""Controllers: anything that maps an observation with its action mask to a legal action.

``base`` (the :class:`Controller` protocol, the observation reader, the AEC episode loop),
the built-ins (``random_agent``, ``fcfs``, ``dispatcher``, ``planner``) and ``registry``, which
resolves a name, an import path or a checkpoint to a controller. ``gcn`` plays a trained
checkpoint (its network is :mod:`agents.gcn`)."""
