"""The protocol card: what an evaluation ran under, written into every summary, so a number can be cited.

HM3D-OVON results in the literature differ in their success rule, step limit, episode set and camera
without saying so. The card states each of them, names the protocol when the run matches a named one
(`hm3d-ovon`: the authors' settings, docs/spec.md) and otherwise says `custom` and lists what differs,
and carries a short fingerprint of everything but the ovon version, so two results are comparable
exactly when their fingerprints agree. The fingerprint covers the rules and the episode set, not the agent
(whose privileged channel and oracle perception the card states beside it) nor the seeds drawn.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

import ovon
from ovon.dataset.subset import ids_sha256
from ovon.runfolder import flatten

# The authors' settings (arXiv 2409.14296 and the released task config): Stretch embodiment, a 360x640
# portrait camera with 42 deg HFOV, 0.25 m / 30 deg actions, 500 steps, success = STOP within 0.25 m
# (geodesic) of a goal viewpoint, child categories counting, no noise.
NAMED: dict[str, dict[str, Any]] = {
    "hm3d-ovon": {
        "task.kind": "objectnav",
        "task.max_steps": 500,
        "task.success_distance": 0.25,
        "actions.move_forward_m": 0.25,
        "actions.turn_deg": 30.0,
        "actions.look_deg": 30.0,
        "actions.allow_sliding": False,
        "camera.width": 360,
        "camera.height": 640,
        "camera.hfov_deg": 42.0,
        "camera.height_m": 1.31,
        "embodiment.radius_m": 0.17,
        "embodiment.height_m": 1.41,
        "noise.actuation": "none",
        "noise.odometry": False,
    },
}


SUCCESS_RULES = {
    "objectnav": "STOP with the geodesic distance to the nearest goal viewpoint below success_distance; goals are "
    "every instance of the category and of its child categories",
    "pointnav": "STOP with the geodesic distance to the goal point below success_distance",
}


def protocol_settings(config: dict) -> dict[str, Any]:
    """The protocol-relevant settings of a run config (`run.json`: an EvalConfig as a dict)."""
    sim, task = config.get("sim") or {}, config.get("task") or {}
    agent, cam, noise = sim.get("agent") or {}, sim.get("camera") or {}, sim.get("noise") or {}
    actuation, odometry = noise.get("actuation", "none"), bool(noise.get("odometry", False))
    kind = task.get("kind", "objectnav")
    return {
        "task": {
            "kind": kind,
            "max_steps": task.get("max_steps"),
            "success_distance": task.get("success_distance"),
            "success_rule": SUCCESS_RULES.get(kind, ""),
        },
        "actions": {
            "move_forward_m": agent.get("forward_step"),
            "turn_deg": agent.get("turn_angle_deg"),
            "look_deg": agent.get("look_angle_deg"),
            "allow_sliding": agent.get("allow_sliding"),
        },
        "camera": {
            "width": cam.get("width"),
            "height": cam.get("height"),
            "hfov_deg": cam.get("hfov_deg"),
            "height_m": cam.get("camera_height"),
        },
        "embodiment": {"radius_m": agent.get("radius"), "height_m": agent.get("height")},
        "noise": {  # a setting of a model that is off is not part of the protocol
            "actuation": actuation,
            "actuation_multiplier": noise.get("actuation_multiplier", 1.0) if actuation != "none" else None,
            "odometry": odometry,
            "odometry_mode": noise.get("odometry_mode", "bounded") if odometry else None,
        },
    }


def differences(settings: dict, name: str) -> list[str]:
    """What differs from the named protocol, e.g. "camera.width 72 (hm3d-ovon: 360)"."""
    flat = flatten(settings)
    return [f"{k} {flat.get(k)!r} ({name}: {v!r})" for k, v in NAMED[name].items() if flat.get(k) != v]


def protocol_card(config: dict, episodes: dict, agent: dict) -> dict:
    """`episodes`: {"set": "whole splits" | subset name, "splits": {split: count}, "seeds": [...], and "ids_sha256"
    of the (split, scene id, episode id) list}; `agent`: {"privileged": bool, "oracle_perception": bool,
    "description": str}."""
    settings = protocol_settings(config)
    body = {**settings, "episodes": episodes, "agent": agent}
    diffs = {n: differences(settings, n) for n in NAMED}
    matched = [n for n, d in diffs.items() if not d]
    # What makes two results comparable: the rules and the episodes, not the agent or the seeds drawn.
    same = {**settings, "episodes": {k: episodes.get(k) for k in ("splits", "ids_sha256")}}
    fingerprint = hashlib.sha256(json.dumps(same, sort_keys=True).encode()).hexdigest()[:12]
    return {
        "name": matched[0] if matched else "custom",
        "differs_from": {n: d for n, d in diffs.items() if d},
        **body,
        "ovon_version": ovon.__version__,
        "fingerprint": fingerprint,
    }


def agent_facts(agent: str, kwargs: dict, remote_privileged: bool = False) -> dict:
    """Whether the agent reads ground truth: the privileged channel (experts) or oracle perception (the
    semantic frame behind an `oracle` detector or value scorer, or an `oracle-vl` policy encoder)."""
    from ovon.agents import load_agent_class
    from ovon.agents.remote import is_remote
    from ovon.agents.served import checkpoint_file

    if is_remote(agent):
        # a served agent is a black box: what the run allowed it, its perception not stated
        return {"privileged": bool(remote_privileged), "oracle_perception": None, "description": "served agent"}
    cls = load_agent_class(agent)
    describe = getattr(cls, "describe", None)
    try:
        description = str(describe(**kwargs)) if callable(describe) else agent
    except Exception:  # noqa: BLE001 - a plug-in's describe must not stop its evaluation; the name stands in
        description = agent
    oracle = "oracle" in description.lower()
    path = checkpoint_file(kwargs.get("checkpoint"))
    if path is not None:
        from ovon.models.policy import read_policy_file

        image = (read_policy_file(str(path), "--checkpoint").get("encoder_config") or {}).get("image", "")
        oracle = oracle or str(image).startswith("oracle")
        description += f" (policy encoder {image})" if image else ""
    return {
        "privileged": bool(getattr(cls, "privileged", False)),
        "oracle_perception": oracle,
        "description": description,
    }


def episode_set(specs_by_split: dict[str, list], seeds, kind: str) -> dict:
    """The card's episode set: which episodes (a description, and the hash of their ids) and the seeds."""
    return {
        "set": kind,
        "splits": {s: len(v) for s, v in sorted(specs_by_split.items())},
        "ids_sha256": ids_sha256((split, s.scene_key, s.episode_id) for split, v in specs_by_split.items() for s in v),
        "seeds": sorted(int(s) for s in seeds),
    }


def card_line(card: dict) -> str:
    """One line under a table: the protocol's name, fingerprint and what differs from the named one."""
    diffs = "; ".join(d for ds in card.get("differs_from", {}).values() for d in ds)
    line = f"Protocol: {card['name']} (fingerprint {card['fingerprint']}; episodes: {card['episodes']['set']})"
    return line + (f"; differs from hm3d-ovon: {diffs}" if diffs else "")
