"""The episode row, declared once (roboview.eval.running.row), and "privileged" read from the policy config as
run.json records it, not from a list of names."""

from dataclasses import dataclass

import pytest

from roboview.eval.running.results import is_privileged_run
from roboview.eval.running.row import INFRA_ERROR, STATUS_OK, EpisodeRow
from roboview.policies.base import PolicyConfig
from roboview.tasks import load_task

pytestmark = pytest.mark.slow

RECORD = {"instance_id": "0123456789abcdef", "split": "color", "value": "red", "context_id": "c0"}


def test_a_row_is_the_record_then_the_episode_then_the_policy_columns():
    row = EpisodeRow(
        RECORD,
        repeat=2,
        episode_seed=7,
        success=False,
        steps=120,
        duration_s=1.5,
        policy="vision",
        failure_reason=load_task("pick_place").timeout_failure(120),
        extra={"vlm_calls": 3, "policy": "not this one"},
    ).as_dict()
    assert list(row)[: len(RECORD)] == list(RECORD)
    assert row["status"] == STATUS_OK and row["policy"] == "vision" and row["vlm_calls"] == 3
    assert row["failure_reason"] == "object not released inside the box within 120 steps"
    assert "conformance" not in row  # the evaluator adds the verdict when it stores the row
    assert (
        EpisodeRow(
            RECORD, 0, 7, False, 0, 0.0, None, "lost", status=INFRA_ERROR, conformance="identical"
        ).as_dict()["conformance"]
        == "identical"
    )


def test_a_row_refuses_an_unknown_status_and_a_successful_failure():
    with pytest.raises(ValueError, match="'crashed'; allowed: ok, infra_error"):
        EpisodeRow(RECORD, 0, 7, False, 1, 0.1, "p", "boom", status="crashed")
    with pytest.raises(ValueError, match="no failure reason"):
        EpisodeRow(RECORD, 0, 7, True, 1, 0.1, "p", "dropped it")


def test_privileged_comes_from_the_policy_config_not_from_its_name():
    @PolicyConfig.register_subclass("oracle_for_test")
    @dataclass
    class OracleConfig(PolicyConfig):
        privileged = True

    try:
        assert is_privileged_run({"policy": "oracle_for_test"})  # run.json without the key: the type says
        assert is_privileged_run({"policy": "expert"}) and not is_privileged_run({"policy": "vision"})
        assert not is_privileged_run({"policy": "expert", "privileged": False})  # recorded: the record wins
        assert is_privileged_run({"policy": "renamed", "privileged": True})
    finally:
        PolicyConfig._choice_registry.pop("oracle_for_test", None)
