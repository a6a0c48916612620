"""Row names that say what a run uses: the agent (and its perception: "oracle detection", "oracle
perception", "privileged"), and the evaluation noise.

A run evaluated with an explicit `--name` keeps it. Otherwise the agent class may describe itself
(`describe(**agent_kwargs) -> str`, e.g. "VLFM, oracle detection, oracle-vl value"); the privileged
built-in experts say so.
"""

from __future__ import annotations

BUILTIN_LABELS = {
    "frontier": "frontier expert (privileged)",
    "shortest-path": "shortest path (privileged)",
}


def noise_label(meta: dict) -> str:
    """ "" without noise, else e.g. "actuation:ilqr, odometry" (from the run's sim.noise)."""
    noise = (meta.get("sim") or {}).get("noise") or {}
    parts = []
    if noise.get("actuation", "none") != "none":
        mult = float(noise.get("actuation_multiplier", 1.0))
        parts.append(f"actuation:{noise['actuation']}" + ("" if mult == 1.0 else f"*{mult:g}"))
    if noise.get("odometry"):
        parts.append("odometry" + (":drift" if noise.get("odometry_mode") == "drift" else ""))
    return ", ".join(parts)


def agent_label(meta: dict) -> str:
    """The row name of a run without its noise (see the module docstring)."""
    agent = str(meta.get("agent", ""))
    name = meta.get("name")
    if name and name != agent:
        return str(name)
    if agent in BUILTIN_LABELS:
        return BUILTIN_LABELS[agent]
    try:
        from ovon.agents import load_agent_class

        describe = getattr(load_agent_class(agent), "describe", None)
        if callable(describe):
            return str(describe(**dict(meta.get("agent_kwargs") or {})))
    except Exception:  # a report must render even when the agent's package is gone
        pass
    return str(name or agent or "run")


def run_label(meta: dict) -> str:
    """Agent label plus the noise, so runs of one agent with and without noise get distinct rows."""
    noise = noise_label(meta)
    label = agent_label(meta)
    return f"{label} [noise: {noise}]" if noise else label
