"""Everything that acts on the vertiport or measures it, in layers that import only downward:

* :mod:`agents.common`: plumbing (atomic writes, seed ranges);
* :mod:`agents.controllers`: the built-in controllers and the registry;
* :mod:`agents.gcn`: the learned ATC (models, distribution, inference controller) and, in
  :mod:`agents.gcn.train`, its training;
* :mod:`agents.evaluate`, :mod:`agents.render`, :mod:`agents.bench`, :mod:`agents.studies`:
  the tools.

``docs/architecture.md`` draws the layers."""
