"""VLM-driven agents (the paper's SimpleAgent and MOKA), the Semantic Grounding Layer, and the one
OpenAI-compatible client they all speak through (`roboview.policies.vlm.client`)."""
