"""Shared fixtures; the helpers the test modules import are in helpers.py."""

from __future__ import annotations

import pytest
from helpers import small_config

from ipp_toolkit.config.schema import EnvConfig


@pytest.fixture
def config() -> EnvConfig:
    return small_config()
