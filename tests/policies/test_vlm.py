"""The VLM path against real HTTP servers on 127.0.0.1: the real `openai` client, both agents, SGL.

Every way a model or a server misbehaves (prose instead of JSON, a refusal, points outside the image,
a 429 then success, a timeout, a 500 storm, a server that dies) ends in an answer after a retry or
in a recorded failure — never a crashed run — and a rerun re-asks nothing that was cached.
"""

import json
import threading

import numpy as np
import pandas as pd
import pytest

from roboview.policies.base import Episode
from roboview.policies.errors import TransientPolicyError
from roboview.policies.factory import make_policy
from roboview.policies.types import policy_config
from roboview.policies.vlm.client import Endpoint, VLMAnswerError, VLMClient
from roboview.policies.vlm.common import check_point
from roboview.policies.vlm.sgl import SGLConfig, refine
from roboview.policies.vlm.standin import MODEL_NAME, ClassicCVModel
from roboview.tasks import make_env
from roboview.variation.factors import baselines
from roboview.variation.instances import TaskInstance, episode_seed
from tests.helpers.vlm_servers import ScriptedServer

pytestmark = pytest.mark.slow

POINTS = {"object_point": [10, 20], "target_point": [30, 40]}


class Echo:
    """A model that answers every prompt with the same JSON."""

    name = "echo"

    def __init__(self, answer=POINTS):
        self.answer_text = json.dumps(answer)

    def answer(self, prompt, images):
        return self.answer_text


@pytest.fixture()
def server():
    servers = []

    def start(script=(), model=None):
        s = ScriptedServer(model or Echo(), script)
        servers.append(s)
        return s

    yield start
    for s in servers:
        s.close()


def client(url, tmp_path, **kw):
    settings = dict(timeout_s=2.0, max_retries=2, cache_dir=str(tmp_path / "cache")) | kw
    return VLMClient(Endpoint(url, "m", **settings))


IMAGE = np.full((32, 32, 3), 128, np.uint8)


def check_points(answer):
    return check_point(answer["object_point"], "object_point", 64, 64), check_point(
        answer["target_point"], "target_point", 64, 64
    )


def test_answers_are_cached_and_keyed_by_the_image(server, tmp_path):
    s = server()
    c = client(s.url, tmp_path)
    assert c.ask_json("where?", [IMAGE]) == POINTS
    assert c.ask_json("where?", [IMAGE]) == POINTS  # from the disk cache
    assert len(s.requests) == 1 and c.take_stats()["vlm_cache_hits"] == 1
    other = IMAGE.copy()
    other[0, 0] = 0  # one pixel differs: a new question
    c.ask_json("where?", [other])
    assert len(s.requests) == 2
    assert s.requests[0]["temperature"] == 0 and s.requests[0]["model"] == "m"


def test_the_key_comes_from_the_named_variable_and_is_never_stored(server, tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOVIEW_TEST_KEY", "sk-test-123")
    s = server()
    c = client(s.url, tmp_path, api_key_env="ROBOVIEW_TEST_KEY")
    c.ask_json("where?", [IMAGE])
    assert s.headers[0]["authorization"] == "Bearer sk-test-123"
    stored = "".join(p.read_text() for p in (tmp_path / "cache").rglob("*.json"))
    assert stored and "sk-test-123" not in stored


def test_prose_gets_one_repair_request(server, tmp_path):
    s = server([("text", "Sure! The object is at the left.")])
    c = client(s.url, tmp_path)
    assert c.ask_json("where?", [IMAGE]) == POINTS
    assert len(s.requests) == 2
    repair = s.requests[1]["messages"]
    assert repair[1] == {"role": "assistant", "content": "Sure! The object is at the left."}
    assert "not JSON" in repair[2]["content"]


@pytest.mark.parametrize(
    "script, error",
    [
        ([("text", "I cannot help."), ("text", "Still no JSON.")], "not JSON"),
        ([("text", '{"object_point": [99, 5], "target_point": [1, 1]}')] * 2, "lies outside the 64x64 image"),
        ([("refusal", "I can't assist with that.")], "refused"),
        ([("status", 401)], "HTTP 401"),
    ],
)
def test_unusable_answers_raise_after_one_repair(server, tmp_path, script, error):
    s = server(script)
    c = client(s.url, tmp_path)
    with pytest.raises(VLMAnswerError, match=error):
        c.ask_json("where?", [IMAGE], check_points)
    assert not list((tmp_path / "cache").rglob("*.json"))  # failures are never cached


def test_transient_errors_are_retried_with_backoff(server, tmp_path):
    s = server([("status", 429), ("status", 503)])
    c = client(s.url, tmp_path)
    assert c.ask_json("where?", [IMAGE], check_points) == ((10, 20), (30, 40))
    assert len(s.requests) == 3  # two retried by the openai client, then the answer
    assert c.take_stats()["vlm_requests"] == 1


@pytest.mark.parametrize("script", [[("status", 500)] * 3, [("sleep", 3.0)] * 3, [("drop", None)] * 3])
def test_persistent_transient_errors_become_transient_policy_errors(server, tmp_path, script):
    s = server(script)
    c = client(s.url, tmp_path, timeout_s=0.5)
    with pytest.raises(TransientPolicyError):
        c.ask_json("where?", [IMAGE])


def test_a_dead_server_is_a_transient_error(server, tmp_path):
    s = server()
    url = s.url
    s.close()
    with pytest.raises(TransientPolicyError, match="APIConnectionError"):
        client(url, tmp_path, max_retries=0).ask_json("where?", [IMAGE])


def test_requests_in_flight_are_bounded(server, tmp_path):
    s = server()
    s.delay_s = 0.2
    clients = [client(s.url, tmp_path / str(i), max_in_flight=2) for i in range(5)]
    threads = [threading.Thread(target=c.ask_json, args=(f"q{i}", [IMAGE])) for i, c in enumerate(clients)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(s.requests) == 5 and s.max_active == 2


@pytest.mark.parametrize(
    "settings, why",
    [
        (
            {"base_url": "http//x", "model": "m"},
            r"^--policy.endpoint.base_url='http//x' must be an http\(s\)",
        ),
        ({"base_url": "http://127.0.0.1:1/v1", "model": ""}, "^--policy.endpoint.model is empty"),
        ({"model": "m", "max_in_flight": 0}, r"--policy.endpoint.max_in_flight=0: need > 0, ≥ 0 and ≥ 1$"),
        ({"model": "m", "camera": "ceiling"}, "unknown camera 'ceiling'"),
    ],
)
def test_bad_endpoints_fail_before_any_work(settings, why):
    camera = {"camera": settings.pop("camera")} if "camera" in settings else {}
    with pytest.raises(ValueError, match=why):
        policy_config("vlm_simple", endpoint=Endpoint(**settings), **camera)


# --- SGL: stages 2 and 3 on parsed scenes ---------------------------------------------------------


def obj(kind, name, color, cats=("geometry",), **kw):
    return {
        "object_type": kind,
        "name": name,
        "color": color,
        "category": [name, *cats],
        "state": "solid",
        "size": "small",
        "position": "normal",
    } | kw


BOX = obj("receiver object", "box", "yellow", ("container",), state="hollow", size="normal")


def test_sgl_refines_a_generic_noun_with_the_color():
    g = refine("put the small object into the yellow box", [obj("manipulation object", "cube", "red"), BOX])
    assert (g.refined, g.ambiguous, g.attribute) == (
        "put the small red cube into the yellow box",
        True,
        "color",
    )


def test_sgl_follows_the_priority_color_state_size_position():
    scene = [
        obj("manipulation object", "cube", "red", size="small", position="left"),
        obj("other object", "pyramid", "red", size="big", position="right"),
        BOX,
    ]
    # Both red and solid: color and state do not tell them apart, size does (and is not said twice).
    g = refine("put the small geometry into the box", scene)
    assert g.attribute == "size" and g.refined == "put the small cube into the box"
    assert refine("put the geometry into the box", scene).refined == "put the small cube into the box"
    scene[1]["size"] = "small"
    assert refine("put the geometry into the box", scene).attribute == "position"
    scene[1]["color"] = "blue"
    assert refine("put the geometry into the box", scene).refined == "put the red cube into the box"


def test_sgl_leaves_an_unambiguous_instruction_alone():
    g = refine("put the cube into the box", [obj("manipulation object", "cube", "red", cats=()), BOX])
    assert (g.refined, g.ambiguous) == ("put the cube into the box", False)


# --- the agents against the stand-in over HTTP -----------------------------------------------------


def _instance(**values):
    return TaskInstance("color", ("color",), baselines() | values, "base")


def _run(policy, env, instance, repeat=0, max_steps=90):
    seed = episode_seed(instance.context_id, repeat)
    obs, _ = env.reset(seed=seed, options={"instance": instance})
    policy.reset(Episode.of(env, seed))
    for _ in range(max_steps):
        obs, _, success, truncated, _ = env.step(policy.select_action(obs))
        if success or truncated:
            break
    return success, policy.episode_record()


@pytest.fixture(scope="module")
def standin():
    s = ScriptedServer(ClassicCVModel())
    yield s
    s.close()


@pytest.fixture(scope="module")
def rgbd_env():
    env = make_env("pick_place", cameras=("front",), depth=True, image_size=224)
    yield env
    env.close()


@pytest.mark.parametrize("agent", ["vlm_simple", "vlm_moka"])
def test_agents_succeed_on_red_and_say_why_they_fail_on_gold(standin, rgbd_env, tmp_path, agent):
    config = policy_config(agent, endpoint=Endpoint(standin.url, MODEL_NAME, cache_dir=str(tmp_path)))
    policy = make_policy(config, rgbd_env)
    success, record = _run(policy, rgbd_env, _instance())
    assert success and record["vlm_requests"] >= 1
    if agent == "vlm_moka":
        assert record["moka_object_description"] == "small red cube" and record["moka_grasp_mark"] == 1
    # Gold merges with the yellow box: the stand-in's most salient blob is then the arm's wrist, which
    # the agent grasps at (vlm_simple) or finds no solid under (vlm_moka).
    success, record = _run(policy, rgbd_env, _instance(color="gold"))
    assert not success
    if agent == "vlm_simple":
        assert np.hypot(*np.subtract(record["vlm_object_point"], (148, 117))) > 20  # not at the object
    else:
        assert policy.failure_reason == "grasp mark hits no graspable solid"
    # Same question, same answer, from the cache.
    n = len(standin.requests)
    _run(policy, rgbd_env, _instance(color="gold"), max_steps=2)
    assert len(standin.requests) == n


def test_sgl_records_the_refined_instruction(standin, rgbd_env, tmp_path):
    config = policy_config("vlm_simple", endpoint=Endpoint(standin.url, MODEL_NAME, cache_dir=str(tmp_path)))
    # the SGL asks the agent's own endpoint
    policy = make_policy(SGLConfig(enable=True).wrap(config), rgbd_env)
    assert policy.name == "vlm_simple+sgl"
    success, record = _run(policy, rgbd_env, _instance(color="blue"))
    assert success
    assert (
        record["sgl_instruction"] == "put the small blue cube into the yellow box" and record["sgl_ambiguous"]
    )
    assert record["vlm_requests"] == 2  # the scene parse and the points
    prompts = [m["messages"][0]["content"][0]["text"] for m in standin.requests[-2:]]
    assert "manipulation object" in prompts[0] and "small blue cube" in prompts[1]


@pytest.fixture(scope="module")
def tiny_bench(tiny_benchmark):
    return tiny_benchmark


def test_a_misbehaving_server_never_crashes_an_evaluation_and_resume_reasks_nothing(tiny_bench, tmp_path):
    from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig
    from roboview.pipelines.evaluate import run as evaluate

    bench = tiny_bench
    # Episode by episode (one worker, in order): prose twice, a refusal, a 500 storm, then answers.
    script = [("text", "no"), ("text", "no"), ("refusal", "nope"), *[("status", 500)] * 9]
    s = ScriptedServer(ClassicCVModel(), script)
    s.retry_after_ms = 1  # what the storm is called matters here, not how long the client waits between tries
    try:

        def run(out):
            endpoint = Endpoint(
                s.url, MODEL_NAME, cache_dir=str(tmp_path / "cache"), max_retries=2, timeout_s=5.0
            )
            config = policy_config("vlm_simple", endpoint=endpoint)
            return evaluate(
                EvaluateConfig(
                    BenchmarkConfig(str(bench), "color"),
                    config,
                    EvalConfig(n_repeats=1, limit=5, num_workers=1, max_steps=8, image_size=128),
                    str(out),
                )
            )

        result = run(tmp_path / "eval")
        rows = pd.read_json(tmp_path / "eval" / "episodes.jsonl", lines=True)  # in the order they ran
        assert result.episodes == 5 and result.infra_errors == 0 and len(rows) == 6
        reasons = rows["failure_reason"].tolist()
        assert "unusable answer after one repair request" in reasons[0]
        assert "refused" in reasons[1]
        assert "policy error after 2 retries" in reasons[2] and "InternalServerError" in reasons[2]
        # The 500 storm is an endpoint outage, not the agent's failure: run again after the pass, answered then.
        assert rows["status"].tolist() == ["ok", "ok", "infra_error", "ok", "ok", "ok"]
        assert (rows["instance_id"][5], rows["repeat"][5]) == (rows["instance_id"][2], rows["repeat"][2])
        assert rows["vlm_requests"].iloc[3:].tolist() == [1, 1, 1]
        asked = len(s.requests)
        # Resume: nothing left to run. A fresh folder: every answered question comes from the cache.
        assert run(tmp_path / "eval").new_episodes == 0
        run(tmp_path / "again")
        again = pd.read_json(tmp_path / "again" / "episodes.jsonl", lines=True)
        assert len(s.requests) == asked + 2  # only the two the agent failed are asked again
        assert again["vlm_cache_hits"].iloc[2:].tolist() == [1, 1, 1]
    finally:
        s.close()


def test_the_vlm_fairness_screen_is_reported_with_its_agreement_with_the_gate(tmp_path):
    from roboview.pipelines.build_benchmark import BuildConfig
    from roboview.pipelines.build_benchmark import run as build

    no = ("text", json.dumps({"analysis": "The object is hard to make out.", "final_answer": "no"}))
    s = ScriptedServer(ClassicCVModel(), [no] * 3 + [("text", "not json"), ("text", "still not")])
    try:
        out = tmp_path / "bench"
        build(
            BuildConfig(
                output_dir=str(out),
                preset="tiny",
                image_size=64,
                num_workers=1,
                vlm_screen=Endpoint(s.url, MODEL_NAME, cache_dir=""),
            )
        )
    finally:
        s.close()
    manifest = json.loads((out / "benchmark.json").read_text())
    screen = manifest["vlm_screen"]
    rows = pd.concat([pd.read_parquet(out / "data" / f"{split}.parquet") for split in manifest["splits"]])
    answers = rows.set_index("instance_id")["fairness"].map(lambda f: f["vlm_answer"])
    n_no = int((answers == "no").sum())
    # The gate passes all 57. The screen said no to the first three (scripted) and to what the stand-in
    # itself cannot make out, and failed on the fourth.
    assert manifest["rejected"] == 0 and screen["screened"] == 56 and screen["errors"] == 1 and n_no >= 3
    assert screen["table"] == {
        "gate_pass_vlm_yes": 56 - n_no,
        "gate_pass_vlm_no": n_no,
        "gate_fail_vlm_yes": 0,
        "gate_fail_vlm_no": 0,
    }
    assert screen["pass_rate"] == round((56 - n_no) / 56, 4) and not screen["meets_paper_target"]
    assert screen["cohens_kappa"] == 0.0  # one rater says "pass" to everything: chance-level agreement
    assert len(screen["disagreements"]) == n_no
    assert sum(d["analysis"] == "The object is hard to make out." for d in screen["disagreements"]) == 3
    color = (
        pd.read_parquet(out / "data" / "color.parquet")["fairness"].map(lambda f: f["vlm_answer"]).tolist()
    )
    assert color[:4] == ["no", "no", "no", "error"]  # one worker: instances in order
    decisions = pd.read_csv(out / "vlm_screen.csv")
    assert len(decisions) == 56 and (decisions["verdict"] == "reject").sum() == n_no
    assert set(decisions["reviewer"]) == {f"vlm:{MODEL_NAME}"}
    assert (out / "contact_sheet" / "index.html").read_text().count("DISAGREES with the gate") == n_no
    assert "Cohen's κ 0.0" in (out / "README.md").read_text()


def test_report_and_probe_read_the_agents_columns(standin, tiny_bench, tmp_path):
    from roboview.eval.campaign.grounding_probe import neighbours
    from roboview.eval.running.agents import color_words, describe_agents, head_noun
    from roboview.pipelines.probe_grounding import BenchmarkPath, ProbeConfig
    from roboview.pipelines.probe_grounding import run as probe

    assert color_words("small dark red cube") == ["darkred"] and color_words("small object") == []
    assert head_noun("small gray cube") == "cube"
    rows = pd.DataFrame(
        {
            "policy": ["vlm_moka"] * 4,
            "vlm_requests": [3, 3, 2, 0],
            "vlm_cache_hits": [0, 0, 1, 3],
            "moka_object_description": ["small red cube", "small gray cube", "small object", None],
        }
    )
    agents = describe_agents(rows)["vlm_moka"]
    assert agents["vlm"]["requests"] == 8 and agents["vlm"]["cache_hits"] == 4
    assert agents["descriptions"]["head_nouns"] == {"cube": round(2 / 3, 4), "object": round(1 / 3, 4)}
    assert agents["descriptions"]["without_color"] == round(1 / 3, 4)
    # The probe re-renders the frames of a real MOKA run and regrounds with neighbouring colour names.
    assert len(neighbours("red", 2)) == 2 and "red" not in neighbours("red", 2)
    from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig
    from roboview.pipelines.evaluate import run as evaluate

    bench = tiny_bench
    endpoint = Endpoint(standin.url, MODEL_NAME, cache_dir=str(tmp_path / "c"))
    config = policy_config("vlm_moka", endpoint=endpoint)
    evaluate(
        EvaluateConfig(
            BenchmarkConfig(str(bench), "color"),
            config,
            EvalConfig(n_repeats=1, limit=3, num_workers=1, max_steps=2, image_size=224),
            str(tmp_path / "e"),
        )
    )
    result = probe(
        ProbeConfig(
            results=str(tmp_path / "e" / "episodes.parquet"),
            benchmark=BenchmarkPath(str(bench)),
            output_dir=str(tmp_path / "p"),
            neighbours=3,
        )
    )
    assert result["episodes"] == 3 and result["cases"] == 9
    assert result["rises"] == sum(c["rise"] > 0.03 for c in result["detail"])
    assert all(c["base"] > 0 for c in result["detail"])  # each description grounded in its own frame
