"""The paper's appendix prompts of F and G, verbatim (``--prompts paper``).

``PAPER_F_PROMPT`` is sent as F's user message with the trajectory render; F's structured answer
then carries the paper's three parts by name (``outcome``, ``concerns``, ``suggestions``).
``PAPER_G_PROMPT`` is G's user message with the current render; ``{analysis}`` stands where the
appendix writes "[analysis from F]". Neither prompt has a system message in the paper, so none is
sent. The tool is the paper's ``propose_move_instruction`` (:func:`adaptenv.adapt.llm.move_tool`).
"""

from __future__ import annotations

PAPER_F_PROMPT = """Analyze the robot navigation paths shown in this floor plan and provide:

- Success assessment: Did the robot complete its navigation task successfully?
- Intermediate concerns: What issues or risks occurred during navigation (e.g., close proximity to obstacles, narrow clearances, suboptimal routing)?
- Targeted adaptations: What specific improvements or training scenarios should be implemented to address these concerns?"""

PAPER_G_PROMPT = """Analysis of agent's trajectory.
{analysis}

Given the analysis of the agent's trajectory, make the environment more challenging for object navigation.

Select ONE object visible in the scene and propose a single move (change in x, y coordinates) that:
- Creates navigation challenges based on the analysis suggestions
- Maintains realism (objects in plausible locations)
- Stays within apartment bounds
Use the `propose_move_instruction` function to specify the move.

Constraints:
- Apartment uses normalized 100x100 grid (x:[0,100], y:[0,100])
- Example: sofa at x=27, y=5, rotation=0
- Keep objects inside walls
- Don't block doorways completely (but can reduce clearances)
- Avoid overlapping with other objects"""
