"""The wire formats of served policies, imported by both sides: the clients in `roboview.policies` and the
servers (`roboview.policies.serving.batching`, `roboview-serve-policy`).

    openpi_wire      openpi's websocket protocol: observation layouts, request and answer shapes, the episode message
    vla_eval_specs   vla-eval's HELLO specs (action, state and camera conventions) negotiated onto the env
    batching         the batching server: one model for every connection, requests batched across them
"""
