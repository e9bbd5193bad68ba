"""A shipped COMA policy is one COMA's training moved, and the default is one of them."""

from __future__ import annotations

import json

import pytest
import torch
from helpers import tiny_coma, tiny_env

from coma.persistence import (
    DEFAULT_SHIPPED,
    SHIPPED_POLICIES,
    build_networks,
    save_policy,
    shipped_policy,
    untrained_reason,
)


@pytest.mark.parametrize("name", sorted(SHIPPED_POLICIES))
def test_every_shipped_policy_was_moved_by_training(name):
    assert untrained_reason(shipped_policy(SHIPPED_POLICIES[name])) is None


def test_the_default_is_a_shipped_trained_policy():
    assert DEFAULT_SHIPPED in SHIPPED_POLICIES


def _start(tmp_path, best_update):
    config = tiny_coma(seed=3)
    torch.manual_seed(config.seed)
    networks = build_networks(config, tiny_env())
    path = tmp_path / "policy.pt"
    save_policy(path, networks)
    path.with_suffix(".json").write_text(json.dumps({"best_update": best_update}))
    return path, networks


def test_a_start_is_refused_by_its_record_and_by_its_weights(tmp_path):
    path, networks = _start(tmp_path, best_update=0)
    assert "best_update = 0" in untrained_reason(path)
    path, networks = _start(tmp_path, best_update=4)  # a record that claims training
    assert "weights equal the start" in untrained_reason(path)
    with torch.no_grad():
        next(networks.actor.parameters()).add_(1e-3)
    save_policy(path, networks)
    assert untrained_reason(path) is None
    path.with_suffix(".json").unlink()
    assert "cannot be read" in untrained_reason(path)
