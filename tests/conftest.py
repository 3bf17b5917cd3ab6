"""Test isolation: no machine profile from the user's environment leaks into the tests (the CLI
looks at $NURBSCNC_MACHINE and the user's config folder when --machine is not given)."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def _no_user_machine_profile(monkeypatch, tmp_path_factory):
    monkeypatch.delenv("NURBSCNC_MACHINE", raising=False)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path_factory.getbasetemp() / "no-config"))
