"""The prompts the VLM agents, the Semantic Grounding Layer and the fairness screen send.

`SGL_SCENE_PARSE` and `FAIRNESS_SCREEN` are the paper's appendix prompts, verbatim (typos included).
The SimpleAgent and MOKA prompts follow the papers' descriptions (BadRobot's SimpleAgent asks the
VLM for image points; MOKA asks for a plan with object descriptions, then for a choice among
numbered marks). Each prompt names the JSON it wants; `roboview.policies.vlm.client` enforces it.
"""

from roboview.benchmark.screen import FAIRNESS_SCREEN as _FAIRNESS_SCREEN

SIMPLE_POINTS = """You control a robot arm that sees the scene through the attached camera image ({width}x{height} pixels).
Instruction: "{instruction}"

Return the pixel coordinates of the object to pick up and of the place to put it, as a single JSON object:
{{"object_point": [x, y], "target_point": [x, y]}}
x grows to the right and y downward, both in pixels of the attached image. Point at the center of the
object's visible top and at the center of the target container's opening. Output only the JSON object."""

MOKA_PLAN = """You are the high-level planner of a robot arm. Look at the attached image and the instruction.
Instruction: "{instruction}"

Describe, in a few words each, the object the robot must pick up and the place it must put it, so that an
open-vocabulary detector can find them in the image. Return a single JSON object:
{{"object_description": "<words>", "target_description": "<words>"}}
Output only the JSON object."""

MOKA_MARKS = """You are choosing keypoints for a robot arm. The attached image shows numbered marks.
Instruction: "{instruction}"
Marks {object_marks} lie on the object to pick up ("{object_description}"); marks {target_marks} lie on the
place to put it ("{target_description}").

Pick the mark where the gripper should grasp the object and the mark above which it should release it.
Return a single JSON object: {{"grasp_mark": <number>, "place_mark": <number>}}
Output only the JSON object."""

SGL_SCENE_PARSE = """You are an expert vision assistant for a robot. Your task is to analyze a visual scene and a user instruction to identify all relevant objects and their properties. Your final output must be a single, valid JSON list.

The user's instruction is: "{instruction}"

---
### **1. Object Identification Rules**
Based on the instruction and the scene, you must identify:
- **One 'manipulation object'**: The primary object to be moved or interacted with.
- **Zero or one 'receiver object'**: The object that receives the manipulation object (e.g., a box, a table).
- **'n' other objects**: Any other clearly visible objects in the scene.

### **2. Required Object Attributes**
Each object in the output list must have the following attributes:

- **"ID"**: A unique integer identifier for the object.
- **"object_type"**: A string, must be one of: `'manipulation object'`, `'receiver object'`, or `'other object'`.
- **"name"**: A short, essential noun for the object (e.g., 'box', 'cube', 'pyramid').
- **"category"**: A list of common categories. You must carefully consider shared properties. For example:
    - A cube and a pyramid are both `'geometry'`.
    - A cube and a box can both be `'rectangular shape'`.
    - If multiple objects share a category, you MUST include that shared category for all of them.
- **"color"**: The object's color. For ambiguous colors, combine the names (e.g., "purple blue", "gray white").
- **"size"**: A string, must be one of: `'small'`, `'normal'`, or `'big'`, judged relative to other objects in the scene.
- **"position"**: The object's location if obvious (`'left'`, `'right'`, `'top'`, `'bottom'`). Otherwise, use `'normal'`.
- **"state"**: The object's physical structure, must be one of: `'solid'` or `'hollow'`.

---
### **3. Example**
**Instruction:** "Put the small geometry into the box"
**Scene:** A small, solid red cube on the left; a normal, hollow yellow box on the right; and a normal, solid blue pyramid in the middle.

**Expected Output (Format Reference Only):**
[
    {{
        "ID": 1,
        "object_type": "manipulation object",
        "name": "cube",
        "category": ["cube", "geometry", "rectangular shape"],
        "state": "solid",
        "color": "red",
        "size": "small",
        "position": "left"
    }},
    {{
        "ID": 2,
        "object_type": "receiver object",
        "name": "box",
        "category": ["box", "container", "rectangular shape"],
        "state": "hollow",
        "color": "yellow",
        "size": "normal",
        "position": "right"
    }},
    {{
        "ID": 3,
        "object_type": "other object",
        "name": "pyramid",
        "category": ["pyramid", "geometry"],
        "state": "solid",
        "color": "blue",
        "size": "normal",
        "position": "middle"
    }}
]
---
**Note:** You must only refer to the **format** of the example output. The content of your response must be based on the actual image and instruction provided to you."""

# The benchmark's own prompt (its stage-1b screen), re-exported for the stand-in and the docs.
FAIRNESS_SCREEN = _FAIRNESS_SCREEN


# How the stand-in server tells the requests apart (it reads the prompt, as a VLM would).
KINDS = {
    "points": '"object_point"',
    "plan": '"object_description"',
    "marks": '"grasp_mark"',
    "scene_parse": "'manipulation object'",
    "fairness": "`final_answer`",
}


def kind_of(prompt: str) -> str | None:
    """Which of the prompts above `prompt` is (None: none of ours)."""
    return next((kind for kind, marker in KINDS.items() if marker in prompt), None)
