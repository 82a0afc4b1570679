"""The vla-eval side of RoboView: a RoboView benchmark run by vla-eval against any vla-eval model server.

    vla-eval run -c configs/vla_eval/roboview_tiny.yaml --server-url ws://127.0.0.1:8000 --no-docker
    python -m roboview.integrations.vla_eval.convert --results=outputs/vla_eval \
        --benchmark.path=outputs/benchmark --output_dir=outputs/eval/vla_eval

benchmark.py: `RoboViewBenchmark`, the vla-eval benchmark (`roboview.integrations.vla_eval.benchmark:RoboViewBenchmark`) ·
convert.py: vla-eval's export → a RoboView results folder (docs/serving.md, "RoboView inside vla-eval").
"""
