"""The benchmark's Markdown report from its measured rows."""

from __future__ import annotations

from typing import Any

from agents.common.provenance import describe




def _floor_lines(results: dict[str, Any], env_rows: list[dict[str, Any]]) -> list[str]:
    """The report's paragraph on the API floor (empty for results without one)."""
    floor = {r["api"]: r["us_per_step"] for r in results.get("api_floor", [])}
    engine = {r["api"]: r["engine_us_per_step"] for r in env_rows if r["config"] == "paper"}
    parts = []
    for api, name in (("aec", "AEC"), ("single_agent", "single-agent")):
        if api not in floor or api not in engine:
            continue
        share = floor[api] / engine[api]
        verdict = ("so there the ratio over all steps cannot come down to 1.0 whatever the "
                   "simulator costs" if share >= 1.0 else
                   f"which leaves {engine[api] - floor[api]:.1f} µs a step for the whole "
                   "simulator and its observation at a ratio of 1.0")
        parts.append(f"{floor[api]:.1f} µs a step through the {name} API, {share:.2f} times the "
                     f"engine's {engine[api]:.1f} µs a step of `paper`, {verdict}")
    if not parts:
        return []
    moving = max(floor.get(r["api"], 0.0) / r["engine_us_per_moving_step"]
                 for r in env_rows if r["config"] == "paper")
    return [
        "- The floor under that ratio: the benchmark loop's API calls and random choice of a "
        "legal action (without its per-step timers) over an env that does nothing, which "
        "returns a fixed observation with "
        "every action legal, the AEC one behind the same order-enforcing wrapper, costs "
        + "; and ".join(parts) + f". In steps with motion the floor is at most {moving:.2f} "
        "times the engine's cost; the rest of the ratio there is the simulator's own Python, "
        "which only a compiled core would bring down to the engine's cost.",
    ]


def _traffic_lines(rows: list[dict[str, Any]]) -> list[str]:
    """The headline: steps per second under the controllers' own traffic."""
    if not rows:
        return []
    head = next((r for r in rows if (r["workload"], r["config"]) == ("dispatcher", "paper")), rows[0])
    out = [
        "## Under real traffic (the headline)",
        "",
        f"**{head['steps_per_s_median']:,.0f} AEC steps/s under the dispatcher's traffic on the "
        f"paper's vertiport**, {head['times_paper']:,.0f} times the paper's simulator. Each "
        "controller's actions for whole days are recorded first and then replayed through the "
        "AEC env, so only the env is timed (the controller's own cost is not in these rows). "
        "Random legal actions (the next table) strand the fleet within hours and leave most "
        "steps without motion; a controller that keeps the fleet flying is the load users have.",
        "",
        "| traffic | config | days | steps/s (median) | min - max | µs per step | steps with "
        "motion | engine alone µs per step | overhead / engine | overhead / engine, steps with "
        "motion | overhead / engine alone |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        out.append(f"| {r['workload']} | {r['config']} | {r['days']} | {r['steps_per_s_median']:,.0f} | "
                   f"{r['steps_per_s_min']:,.0f} - {r['steps_per_s_max']:,.0f} | "
                   f"{r['total_us_per_step']:.0f} | {100 * r['moving_fraction']:.0f} % | "
                   f"{r['engine_alone_us_per_step']:.1f} | {r['overhead_ratio']:.2f} | "
                   f"{r['moving_overhead_ratio']:.2f} | {r['overhead_ratio_engine_alone']:.2f} |")
    out += ["", f"{rows[0]['repeats']} replays of each, in interleaved rounds; columns as in the "
            "next table.", ""]
    return out


def _fleet_and_planner_lines(results: dict[str, Any]) -> list[str]:
    out = []
    rows = results.get("fleet_sizes") or []
    if rows:
        first = rows[0]
        out += ["### Cost against fleet size (the dispatcher's traffic)", "",
                "| layout | eVTOLs | steps | µs per step | per eVTOL | steps with motion |",
                "|---|---:|---:|---:|---:|---:|"]
        for r in rows:
            out.append(f"| {r['label']} | {r['fleet_size']} | {r['steps']:,} | {r['us_per_step']:.0f} | "
                       f"{r['us_per_step'] / r['fleet_size']:.1f} | {100 * r['moving_fraction']:.0f} % |")
        last = rows[-1]
        growth = (last["us_per_step"] / first["us_per_step"]) / (last["fleet_size"] / first["fleet_size"])
        out += ["", f"From {first['fleet_size']} to {last['fleet_size']} eVTOLs the cost of a step grows "
                f"{last['us_per_step'] / first['us_per_step']:.1f}-fold while the fleet grows "
                f"{last['fleet_size'] / first['fleet_size']:.0f}-fold ({growth:.2f} of linear).", "",
                f"![µs per step against fleet size]({results.get('fleet_size_figure', 'performance_fleet.png')})", ""]
    planner = results.get("planner")
    if planner:
        out += ["### The look-ahead planner", "",
                f"The planner (`planner`: per candidate action a snapshot of the simulator, 40 steps "
                f"of the dispatcher, a restore) makes **{planner['decisions_per_s']:.0f} decisions per "
                f"second** on `{planner['config']}` over {planner['decisions']:,} turns, "
                f"{planner['ms_per_simulated_decision']:.1f} ms for each of the "
                f"{planner['simulated']:,} it simulates (the others have a single candidate, or "
                "a vehicle in transit, and take the dispatcher's choice unsimulated). "
                f"{100 * planner['engine_share']:.0f} % of its time is in the engine's calls "
                f"(overhead / engine {planner['overhead_ratio']:.2f}, overhead / engine alone "
                f"{planner['overhead_ratio_engine_alone']:.2f}); the rest is the simulator's "
                "Python, the dispatcher's rules and the observations it reads. It is the warm "
                "start's teacher, so its speed bounds `make train`.", ""]
    return out


def _traffic_reading(results: dict[str, Any]) -> list[str]:
    """What bounds the speed under traffic, from the profile and the traffic rows."""
    traffic = {(r["workload"], r["config"]): r for r in results.get("traffic") or []}
    head = traffic.get(("dispatcher", "paper"))
    planner = results.get("planner")
    if not head:
        return []
    us, engine_alone = head["total_us_per_step"], head["engine_alone_us_per_step"]
    out = [
        f"- What bounds the speed under traffic: a step of the dispatcher's day on `paper` costs "
        f"{us:.0f} µs, of which the engine alone needs {engine_alone:.0f} µs; the rest is the "
        "simulator's own Python (the step's bookkeeping for each vehicle: motion, the swept "
        "separation of every pair with a mover, arrivals, batteries, delays, the conflict probe), "
        "the observation (the eVTOL graph built from Python rows and converted to float32 once, "
        "the port graph once a step, copies for the caller) and the AEC layer. The profile above "
        "shows no single function above a few per cent of the run on its own: what is left is "
        "many small Python operations per vehicle and per pair, which only a compiled core would "
        "remove.",
    ]
    if planner:
        out.append(
            f"- The planner's time is mostly the simulator's steps in its rollouts (about 40 per "
            f"candidate): {100 * planner['engine_share']:.0f} % in the engine, most of the rest in "
            "the same step code as above, and a smaller share in the dispatcher's rules and the "
            "observations they read. Decisions that need no simulation (a single candidate, a "
            "vehicle in transit) take the dispatcher's choice, and rollout turns with one legal "
            "action do not ask the dispatcher.")
    return out


def _target_lines(results: dict[str, Any]) -> list[str]:
    """Measured against the speed targets (the dispatcher's traffic, one process)."""
    traffic = {(r["workload"], r["config"]): r for r in results.get("traffic") or []}
    fleet = results.get("fleet_sizes") or []
    rows = []
    for config, target in (("paper", 10_000), ("large", 4_000)):
        r = traffic.get(("dispatcher", config))
        if r:
            rows.append((f"AEC steps/s, dispatcher's traffic, `{config}` (median)", f">= {target:,}",
                         f"{r['steps_per_s_median']:,.0f} (min {r['steps_per_s_min']:,.0f})",
                         r["steps_per_s_median"] >= target))
    for config in ("paper", "large"):
        r = traffic.get(("dispatcher", config))
        if r:
            rows.append((f"overhead / engine in steps with motion, `{config}`", "<= 2",
                         f"{r['moving_overhead_ratio']:.2f}", r["moving_overhead_ratio"] <= 2.0))
    check = results.get("separation_check")
    if check:
        rows.append((f"separation check's cost, dispatcher's traffic, `{check['config']}` "
                      "(rules v1 against v0)", "<= 10 %", f"{100 * check['cost']:.1f} %",
                      check["cost"] <= 0.10))
    if len(fleet) > 1:
        growth = ((fleet[-1]["us_per_step"] / fleet[0]["us_per_step"])
                  / (fleet[-1]["fleet_size"] / fleet[0]["fleet_size"]))
        rows.append((f"cost per step, {fleet[0]['fleet_size']} to {fleet[-1]['fleet_size']} eVTOLs",
                     "no worse than linear", f"{growth:.2f} of linear", growth <= 1.0))
    if not rows:
        return []
    out = ["### Against the targets", "", "| measure | target | measured | met |",
           "|---|---|---|---|"]
    out += [f"| {name} | {target} | {value} | {'yes' if met else '**no**'} |"
            for name, target, value, met in rows]
    return out + ["", "`make train` is timed by the run itself: it prints the time of each part "
                  "when it ends (experiments/default-run-rules-v1 gives measured runs).", ""]


def _profile_lines(results: dict[str, Any]) -> list[str]:
    prof = results.get("profile")
    if not prof:
        return []
    workload = ("the dispatcher's traffic" if prof.get("workload") == "dispatcher"
                else "random legal actions")
    out = [f"### Where a step's time goes (cProfile, AEC API, `paper`, {workload}, "
           f"{prof['steps']:,} steps)", "",
           "| function | calls per step | own time | with callees |", "|---|---:|---:|---:|"]
    for e in prof["top"]:
        out.append(f"| `{e['function']}` | {e['calls_per_step']:.2f} | "
                   f"{100 * e['own_share']:.1f} % | {100 * e['cumulative_share']:.1f} % |")
    return out + ["", "Functions called at least once every 100 steps; shares of the profiled "
                  "run's total. The profiler's own cost per call inflates functions that make "
                  "many small calls.", ""]


def report(results: dict[str, Any]) -> str:
    env_rows = results["env"]
    ref = next((r for r in env_rows if (r["api"], r["config"]) == ("single_agent", "paper")), env_rows[0])
    lines = [
        "# Performance",
        "",
        f"Measured by `{results['command']}` on {results['machine']} "
        f"(Python {results['python']}); regenerate with `make bench`.",
        "",
    ]
    if results.get("provenance"):
        lines += [f"Made with {describe(results['provenance'])} (`provenance` in "
                  "`bench.json`).", ""]
    lines += _traffic_lines(results.get("traffic") or [])
    check = results.get("separation_check")
    if check:
        lines += ["## The separation check's cost", "",
                  f"The dispatcher's traffic on `{check['config']}` ({check['days']} days from seed "
                  f"{check['seed']}, median of {check['repeats']} interleaved replays each): "
                  f"{check['on_steps_per_s']:,.0f} AEC steps/s with the separation check (rules "
                  f"v1), {check['off_steps_per_s']:,.0f} without (rules v0): the check costs "
                  f"{100 * check['cost']:.1f} % (target: at most 10 %)"
                  + (f"; the cost of one pair of back-to-back replays has quartiles "
                     f"{100 * check['pair_cost_quartiles'][0]:.1f} % and "
                     f"{100 * check['pair_cost_quartiles'][1]:.1f} %"
                     if check.get("pair_cost_quartiles") else "") + ".", ""]
    lines += _target_lines(results)
    lines += _profile_lines(results)
    lines += _fleet_and_planner_lines(results)
    lines += [
        "## Environment steps per second (one process, random legal actions)",
        "",
        "| API | config | steps/s (median) | min - max | µs per step | steps with motion | "
        "engine µs per step | engine µs per step with motion | engine alone µs per step | "
        "overhead / engine | overhead / engine, steps with motion | overhead / engine alone | "
        "x the paper's 5 steps/s |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in env_rows:
        lines.append(f"| {r['api']} | {r['config']} | {r['steps_per_s_median']:,.0f} | "
                     f"{r['steps_per_s_min']:,.0f} - {r['steps_per_s_max']:,.0f} | "
                     f"{r['total_us_per_step']:.0f} | {100 * r['moving_fraction']:.0f} % | "
                     f"{r['engine_us_per_step']:.1f} | {r['engine_us_per_moving_step']:.0f} | "
                     f"{r['engine_alone_us_per_step']:.1f} | {r['overhead_ratio']:.2f} | "
                     f"{r['moving_overhead_ratio']:.2f} | {r['overhead_ratio_engine_alone']:.2f} | "
                     f"{r['times_paper']:,.0f} |")
    lines += [
        "",
        f"{env_rows[0]['repeats']} runs of {env_rows[0]['steps']:,} steps each, in interleaved "
        "rounds (each round runs every row once); every ratio is the median over the runs of "
        "the ratio within one run. On this kind of virtual machine the same run varies by up to "
        "a third from one minute to the next: read the min - max column.",
        "",
        "- **engine**: wall time inside the simulator's pybullet calls during the timed run "
        "(velocity commands, gust forces, stepping at >= 48 Hz of flight time, position reads, "
        "contact queries, switching bodies between static, dynamic and absent). The engine is "
        "stepped only in steps in which a body moves (**steps with motion**).",
        "- **overhead**: the rest of the run's wall time: the simulator's bookkeeping, "
        "observations, masks, the API layers and the benchmark's own random choice of a legal "
        "action (about 3 µs a step).",
        "- **engine alone**: after each timed run, a second run with the same seed records every "
        "pybullet call with its arguments; the calls of the timed loop are replayed on a fresh "
        "pybullet client with nothing around them but a Python loop, and timed. "
        "**overhead / engine alone** is (run time - replay time) / replay time.",
        "- **overhead / engine, steps with motion**: the same ratio counting only the steps in "
        "which the engine was stepped (each step timed on its own).",
        "",
    ]
    lines += [
        "## Vectorised copies (supersuit's `gym_vec_env_v0`, single-agent env, random legal actions)",
        "",
        "| copies | processes | env steps/s |",
        "|---:|---:|---:|",
    ]
    for r in results["vector"]:
        lines.append(f"| {r['copies']} | {r['processes']} | {r['env_steps_per_s']:,.0f} |")
    lines += ["", "## Policy and training", "", "| measure | value |", "|---|---:|"]
    for r in results["inference"]:
        path = ("torch" if r.get("path", "torch") == "torch"
                else "NumPy forward pass, as the greedy controller plays")
        lines.append(f"| actor latency, batch {r['batch']}, {path} (median / p90) | "
                     f"{r['latency_ms_median']:.2f} / {r['latency_ms_p90']:.2f} ms |")
    t = results["training"]
    lines += [
        f"| training throughput (`make train` config, {t['mode']}, {t['iterations']} PPO iterations) | "
        f"{t['env_steps_per_s']:,.0f} env steps/s |",
        f"| peak memory, training process | {t['peak_memory_mb']:.0f} MB |",
        f"| peak memory, one env running a day | {results['env_peak_memory_mb']:.0f} MB |",
        "",
        "## Reading these numbers",
        "",
        *_traffic_reading(results),
        f"- Under random legal actions the fleet empties its batteries within the first hours of "
        f"the day (docs/results.md) and most vehicles are then out of service, so in "
        f"{100 - 100 * ref['moving_fraction']:.0f} % of the steps ({ref['api']}, {ref['config']}) "
        f"no body moves and the engine is not asked to do anything, while each step still checks "
        f"the action, advances batteries, schedules and the conflict probe and builds an "
        f"observation: {ref['total_us_per_step'] - ref['engine_us_per_step']:.0f} µs of our own "
        f"work a step against {ref['engine_us_per_step']:.1f} µs of engine time. That is why the "
        "random-play rows are not the headline.",
        *_floor_lines(results, env_rows),
        "- The single-agent API skips the AEC wrappers and reward dicts; the larger fleet costs "
        "less than proportionally more per step (per-vehicle work is a small part of a step).",
        "- Vector envs in one process pay per-copy Python and the stacking of observations; "
        "separate processes add inter-process copies of nested Dict observations, which on 2 cores "
        "costs more than it gains.",
        "- Training throughput is bounded by the graph models' forward and backward passes: in "
        "the multi-agent mode every (copy, eVTOL) row is a row of the batch, 256 per step.",
        "",
    ]
    return "\n".join(lines)


