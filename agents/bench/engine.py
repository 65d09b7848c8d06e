"""The engine alone: a run's pybullet calls recorded (a stand-in for the pybullet module inside
:mod:`marl_vertiport.sim.physics`) and replayed in bare pybullet, timed, so the benchmark can
say how much of a step is the engine's own work."""

from __future__ import annotations

import time
from typing import Any


class EngineCallRecorder:
    """Stands in for the pybullet module inside :mod:`marl_vertiport.sim.physics` for one run:
    forwards every call and records it with its arguments, so the run's engine work can be
    replayed in bare pybullet (:func:`replay_engine`). Only calls on the clients opened during
    the recording are kept, and no disconnection: another env of the process that is
    garbage-collected meanwhile disconnects its own client through the same module, which is not
    this run's work (the replay opens and closes a client of its own)."""

    def __init__(self, module: Any) -> None:
        self._module = module
        self.calls: list[tuple[Any, tuple, dict]] = []
        #: The clients opened during the recording, in the order they were opened.
        self.connected: list[int] = []

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._module, name)
        if not callable(attr) or isinstance(attr, type):  # constants and the error class
            return attr
        calls, connected = self.calls, self.connected
        connect, disconnect = self._module.connect, self._module.disconnect

        def call(*args: Any, **kwargs: Any) -> Any:
            result = attr(*args, **kwargs)
            if attr is connect:
                connected.append(result)
                calls.append((attr, args, kwargs))
            elif attr is not disconnect and kwargs.get("physicsClientId") in connected:
                calls.append((attr, args, kwargs))
            return result

        return call

def replay_engine(recorder: EngineCallRecorder, first_timed: int, last_timed: int) -> float:
    """Replay recorded pybullet calls on fresh clients; seconds taken by the calls of the timed
    loop (``calls[first_timed:last_timed]``), with nothing but a loop around them."""
    return replay_engine_spans(recorder, [(first_timed, last_timed)])

def replay_engine_spans(recorder: EngineCallRecorder, spans: list[tuple[int, int]]) -> float:
    """Replay the recorded pybullet calls in order, each recorded client on a fresh one of its
    own; seconds taken by the calls inside ``spans`` (``(first, last)`` index ranges of
    ``recorder.calls``, in order), each span timed as one block with nothing but a loop
    around its calls."""
    from marl_vertiport.sim import physics as physics_module

    p = physics_module.p
    fresh = {recorded: p.connect(p.DIRECT) for recorded in recorder.connected}
    plan = [(fn, args, dict(kwargs, physicsClientId=fresh[kwargs["physicsClientId"]])
             if "physicsClientId" in kwargs else kwargs)
            for fn, args, kwargs in recorder.calls if fn is not p.connect]
    # Indices of recorder.calls -> indices of plan (the connect calls are not replayed).
    shift, index = 0, []
    for fn, _, _ in recorder.calls:
        index.append(len(index) - shift)
        shift += fn is p.connect
    index.append(len(plan))
    elapsed, done = 0.0, 0
    for first, last in spans:
        first, last = index[first], index[last]
        for fn, args, kwargs in plan[done:first]:  # the world as it was when the span began
            fn(*args, **kwargs)
        block = plan[first:last]
        start = time.perf_counter()
        for fn, args, kwargs in block:
            fn(*args, **kwargs)
        elapsed += time.perf_counter() - start
        done = last
    for client in fresh.values():
        p.disconnect(physicsClientId=client)
    return elapsed
