"""Everything that acts on the vertiport or measures it, one layer per folder, each importing
only from the layers below it:

* layer 2, controllers: :mod:`agents.common` (plumbing: atomic writes, seed ranges, agent
  specs, imports from the working directory, provenance), :mod:`agents.execution` (where
  tasks run), :mod:`agents.gcn` (the learned ATC's models, distribution, features, padding) and
  :mod:`agents.controllers` (the built-in controllers, the GCN inference controller, the one
  episode loop, the registry);
* layer 3, evaluation: :mod:`agents.evaluate`, :mod:`agents.sweep`;
* layer 4, training and tools: :mod:`agents.training`, :mod:`agents.curves`,
  :mod:`agents.interop`, :mod:`agents.render`, :mod:`agents.bench`, :mod:`agents.studies`,
  :mod:`agents.checks` and the ``marl-vertiport`` command (:mod:`agents.cli`).

``docs/architecture.md`` draws the layers; ``tests/tools/test_architecture.py`` enforces them."""
