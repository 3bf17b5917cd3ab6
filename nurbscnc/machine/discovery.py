"""Which machine profile a command uses: the discovery order (``--machine``,
``$NURBSCNC_MACHINE``, ``./nurbscnc.toml``, the user's config folder, the bundled default) and
the bundled default's text."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

#: Environment variable naming a profile (discovery step 2).
ENV_MACHINE = "NURBSCNC_MACHINE"
#: Profile file looked for in the current folder (discovery step 3).
LOCAL_PROFILE = "nurbscnc.toml"
#: How a profile was found (``Machine.found_by``), in discovery order.
FOUND_BY_OPTION = "--machine"
FOUND_BY_ENV = "$" + ENV_MACHINE
FOUND_BY_LOCAL = "./" + LOCAL_PROFILE
FOUND_BY_USER = "user config"
FOUND_BY_DEFAULT = "bundled default"


#: The package's data folder (a folder of the installed package: it has compiled modules, so
#: it is never imported from a zip; ``importlib.resources`` and the ``tempfile`` it loads
#: cost 6 ms of every command's start).
PACKAGE_DATA = Path(__file__).resolve().parents[1] / "data"
#: The templates of ``profile init --template``: name → packaged file.
TEMPLATES = {"paper": "default_machine.toml", "router": "router_machine.toml"}


def default_profile_text() -> str:
    """The text of the packaged default profile (the paper's benchmark machine)."""
    return template_text("paper")


def template_text(name: str) -> str:
    """The text of the packaged profile template ``name`` (:data:`TEMPLATES`): ``paper``, the
    default profile (the paper's X-Y table with its 4th-order servo models), or ``router``, a
    stepper-motor router without a servo model."""
    return (PACKAGE_DATA / TEMPLATES[name]).read_text(encoding="utf-8")


def user_profile_path(environ: Mapping[str, str] | None = None) -> str:
    """The user's profile: ``$XDG_CONFIG_HOME/nurbscnc/machine.toml``, or
    ``~/.config/nurbscnc/machine.toml`` when XDG_CONFIG_HOME is unset, empty or relative (as
    the XDG base-directory spec says)."""
    env = os.environ if environ is None else environ
    base = env.get("XDG_CONFIG_HOME", "")
    if not os.path.isabs(base):
        home = env.get("HOME") or os.path.expanduser("~")
        base = os.path.join(home, ".config")
    return os.path.join(base, "nurbscnc", "machine.toml")


def find_machine(
    path: str | None = None, environ: Mapping[str, str] | None = None, cwd: str | None = None
) -> tuple[str | None, str]:
    """Which profile to load: (file or None for the bundled default, how it was found).

    Order, first match wins: ``path`` (``--machine``); ``$NURBSCNC_MACHINE`` when set and
    non-empty (a missing file is then an error when it is read, never skipped); ``nurbscnc.toml``
    in ``cwd`` (default: the current folder) if it exists; :func:`user_profile_path` if it
    exists; the bundled default. ``environ`` defaults to ``os.environ``.
    """
    env = os.environ if environ is None else environ
    if path is not None:
        return str(path), FOUND_BY_OPTION
    if env.get(ENV_MACHINE):
        return env[ENV_MACHINE], FOUND_BY_ENV
    local = os.path.join(cwd, LOCAL_PROFILE) if cwd is not None else LOCAL_PROFILE
    if os.path.isfile(local):
        return (local if cwd is not None else FOUND_BY_LOCAL), FOUND_BY_LOCAL
    user = user_profile_path(env)
    if os.path.isfile(user):
        return user, FOUND_BY_USER
    return None, FOUND_BY_DEFAULT
