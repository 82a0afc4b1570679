"""Policies from their configs: one per env, or a batch for envs stepped in lockstep.

A config wrapped in the SGL (`roboview.policies.vlm.sgl.SGLConfig.wrap`) builds grounded policies itself.
"""

from __future__ import annotations

from roboview.policies.base import AgentView, JointPlanInEE, Policy, PolicyBatch, PolicyConfig
from roboview.tasks.env import TaskEnv


def make_policy_batch(config: PolicyConfig, envs: list[TaskEnv]) -> PolicyBatch:
    """The policies for `envs` run in lockstep: one batched policy when the type builds one (a config wrapped in the SGL
    wraps it), else one policy per env (`make_policy`)."""
    if len(envs) > 1 and not config.privileged:
        native = config.build_batched(AgentView.of(envs[0]), len(envs))
        if native is not None:
            return PolicyBatch([native], batched=True)
    return PolicyBatch([make_policy(config, env) for env in envs], batched=False)


def make_policy(config: PolicyConfig, env: TaskEnv) -> Policy:
    """Build `config`'s policy for `env`: from the env only if the type is privileged."""
    return build_policy(config, env if config.privileged else AgentView.of(env))


def build_policy(config: PolicyConfig, view: AgentView | TaskEnv) -> Policy:
    """`config`'s policy from an agent's view (a privileged type's from the env); one that plans joint targets acts
    through `JointPlanInEE` when its control is an end-effector one."""
    policy = config.build(view)
    control = config.env_control()
    if config.plans_joints and control != "joint":
        model = view.model if isinstance(view, TaskEnv) else view.kinematic_model()
        policy = JointPlanInEE(policy, model, control)
    return policy
