"""Fixtures for the agent tests."""

from __future__ import annotations

import pytest

from search.crowd.agents.dsrnn import DSRNN
from tests.support.agents import make_net


@pytest.fixture
def net() -> DSRNN:
    return make_net()
