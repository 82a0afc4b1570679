"""RoboView: measure whether a robot policy is visually biased.

One package, in rooms that each import only the rooms below them (docs/layout.md):

    core/          CLI plumbing, the worker pool, folders, files, errors
    sim/           the simulated world every task shares
    variation/     the visual factors, colors, variant trees, benchmark instances
    tasks/         one module per task (importing it registers the tasks and their gymnasium ids)
    benchmark/     render, fairness gate, the frozen benchmark folder, conformance
    demos/         scripted-expert demos into LeRobot datasets
    policies/      every policy type; serving/ holds the wire formats clients and servers share
    eval/          running/, statistics/, reporting/, verification/, campaign/ (config, plan, runner, board, audit)
    integrations/  lerobot (lerobot-eval / lerobot-train's `roboview` env) and vla_eval (RoboView inside vla-eval)
    pipelines/     the verbs: `roboview-<verb>` console scripts, `python -m roboview.pipelines.<verb>`

Importing `roboview` itself loads nothing; `import roboview.tasks` registers `RoboView/PickPlace-v0` and the
other tasks' gymnasium ids.
"""

__version__ = "0.5.0"
