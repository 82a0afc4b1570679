"""RoboView: measure whether a robot policy is visually biased.

One package, in rooms that each import only the rooms below them (docs/layout.md):

    core/          CLI plumbing, the worker pool, the registries' discovery, folders, files, errors
    sim/           the simulated world every task shares
    variation/     the visual factors, colors, variant trees, benchmark instances
    tasks/         the registries of tasks, worlds and presets, the world contract, RoboView's own tasks and presets
    libero/        LIBERO's wing (its world, task, factors, presets, expert; LIBERO-plus's camera variants and view
                   factors), on the tasks' floor
    metaworld/     Meta-World's wing (its world, task, factors, presets), on the tasks' floor
    benchmark/     render, fairness gate, the frozen benchmark folder, conformance
    demos/         scripted-expert demos into LeRobot datasets
    policies/      every policy type; serving/ holds the wire formats clients and servers share; vlm/ the VLM agents
    eval/          running/, statistics/, reporting/, verification/, campaign/ (config, plan, runner, board, audit)
    integrations/  lerobot/ (lerobot-eval / lerobot-train's `roboview` env), vla_eval/ (RoboView inside vla-eval),
                   publishing/ (the Hugging Face Hub)
    pipelines/     the verbs, one `roboview-<verb>` console script each (`python -m roboview.pipelines.<verb>`):
                   collect, export_dataset, train, coverage, build_benchmark, publish, evaluate, compare, merge,
                   pair, verify, leaderboard, serve_policy, serve_vlm, report, audit, plan, probe_grounding

Beside the package, not installed: benchmarks/, the throughput and statistics studies (docs/performance.md):
throughput, render_rate, collect_rate, serving, cluster, gpu, policy_latency, torch_threads.sh, verify_rate,
conformance_drift, adaptive, paired_compare, stats_calibration, cv_excess_interval, glm_refits, interval_coverage,
libero_throughput, libero_render, libero_render_rate, libero_expert, libero_vs_lerobot_eval, libero_plus_poses,
libero_plus_noise_cost, metaworld_expert, metaworld_vs_lerobot_eval.

Importing `roboview` itself loads nothing. The tasks, worlds and presets register when a registry is first read
(`roboview.tasks.discover()` does it at once): every module named under the `roboview.tasks` entry-point group, so
`RoboView/PickPlace-v0` and the other tasks' gymnasium ids too.
"""

__version__ = "0.5.0"
