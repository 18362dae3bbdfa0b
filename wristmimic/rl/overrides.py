"""``--set SECTION.FIELD=VALUE`` overrides of a run's configuration, checked against the field they replace.

Sections are the parts of ``config.json`` a user may tune: ``env`` (:class:`~wristmimic.env.config.EnvConfig`),
``ppo`` (:class:`~wristmimic.rl.config.PPOConfig`) and ``scene_config`` (:class:`~wristmimic.scene.SceneConfig`).
Nested fields use dots (``env.object_controller.zero_by_frames=1500000``). A value is read as JSON (``0.5``,
``true``, ``[256, 128]``, ``null``), else as a plain string. The run's ``config.json`` records the resulting
configuration and the override strings.
"""

from __future__ import annotations

import json
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from wristmimic.env.config import check_env_config, env_config_from_dict
from wristmimic.errors import InputError

if TYPE_CHECKING:
    from wristmimic.rl.train import TrainSpec

SECTIONS = ("env", "ppo", "scene_config")


def parse_override(text: str) -> tuple[list[str], Any]:
    """``'env.a.b=1'`` -> (['env', 'a', 'b'], 1); one-line :class:`InputError` for a malformed one."""
    key, sep, raw = text.partition("=")
    path = key.strip().split(".")
    if not sep or len(path) < 2 or path[0] not in SECTIONS or not all(path):
        raise InputError(None, "--set", f"{text!r}", f"SECTION.FIELD=VALUE with SECTION one of {', '.join(SECTIONS)}")
    try:
        value = json.loads(raw)
    except json.JSONDecodeError:
        value = raw
    return path, value


def _checked(key: str, old: Any, new: Any) -> Any:
    """``new`` in the JSON type of ``old`` (an int is accepted for a float field); raises otherwise."""
    if old is None or new is None:
        return new
    if isinstance(old, bool) or isinstance(new, bool):
        ok = isinstance(old, bool) and isinstance(new, bool)
    elif isinstance(old, float):
        ok = isinstance(new, int | float)
        new = float(new) if ok else new
    elif isinstance(old, int):
        ok = isinstance(new, int)
    elif isinstance(old, dict):
        ok = False  # a whole sub-config: set its fields one by one
    else:
        ok = isinstance(new, type(old))
    if not ok:
        raise InputError(None, "--set", f"{key}={json.dumps(new)}", f"a value like the current {json.dumps(old)}")
    return new


def apply_overrides(config: dict[str, Any], overrides: list[str] | tuple[str, ...]) -> dict[str, Any]:
    """A copy of the JSON ``config`` (``{'env': {...}, 'ppo': {...}, 'scene_config': {...}}``) with
    ``overrides`` applied in order; unknown fields and wrong types raise :class:`InputError`."""
    out = json.loads(json.dumps(config))
    for text in overrides:
        path, value = parse_override(text)
        node = out
        for i, name in enumerate(path[:-1]):
            node = node.get(name) if isinstance(node, dict) else None
            if not isinstance(node, dict):
                raise InputError(None, "--set", f"{'.'.join(path[: i + 1])} is not a section", "a known field")
        leaf = path[-1]
        if leaf not in node:
            known = ", ".join(sorted(node))
            raise InputError(None, "--set", f"unknown field {'.'.join(path)}", f"one of {known}")
        node[leaf] = _checked(".".join(path), node[leaf], value)
    return out


def with_overrides(spec: TrainSpec, overrides: list[str] | tuple[str, ...]) -> TrainSpec:
    """``spec`` with its environment, PPO and scene configs overridden (recorded in ``spec.overrides``)."""
    from wristmimic.rl.config import PPOConfig, from_jsonable, preset_env, to_jsonable
    from wristmimic.scene import scene_config_from_dict

    if not overrides:
        return spec
    env = spec.env or preset_env(spec.preset, spec.variant)
    base = {"env": to_jsonable(env), "ppo": to_jsonable(spec.ppo), "scene_config": to_jsonable(spec.scene_config)}
    cfg = apply_overrides(base, overrides)
    try:
        new_env = env_config_from_dict(cfg["env"])
        check_env_config(new_env)
        ppo = from_jsonable(PPOConfig, cfg["ppo"])  # lists become the tuples the fields declare
        scene = scene_config_from_dict(cfg["scene_config"])
    except (ValueError, TypeError) as exc:
        raise InputError(None, "--set", str(exc).splitlines()[0]) from None
    return replace(spec, env=new_env, ppo=ppo, scene_config=scene, overrides=(*spec.overrides, *overrides))
