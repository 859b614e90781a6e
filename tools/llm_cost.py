"""What one LLM-adapted scene costs with gpt-4.1-mini: a recorded `adaptenv adapt` run against a loopback server.

The server (tests/adapt/llm_server.py, 127.0.0.1 only) answers every F and G request of the run
with a plausible answer and reports, as ``usage``, the tokens gpt-4.1-mini would bill for that
request: images by OpenAI's published rule for gpt-4.1-mini (32x32-pixel patches, at most 1536,
times 1.62), text (prompt, tool schema, earlier turns, the answer) at 4 characters per token
(OpenAI's rule of thumb; no tokenizer is a dependency here). adaptenv counts those tokens as it
would count a real server's, so the printed figures are adaptenv's own counts of the run.

    PYTHONPATH=src python tools/llm_cost.py --steps 5 --seed 0 --prompts adaptenv
"""

from __future__ import annotations

import argparse
import base64
import importlib.util
import json
import math
import struct
import sys
import tempfile
from pathlib import Path
from typing import Any

from typer.testing import CliRunner

ROOT = Path(__file__).resolve().parents[1]
#: gpt-4.1-mini image tokens per 32x32 patch and the patch cap (OpenAI's images guide).
PATCH_MULTIPLIER = 1.62
PATCH_CAP = 1536
CHARS_PER_TOKEN = 4.0

F_ANSWER = {"outcome": {"success": True, "failure_mode": None,
                        "summary": "The robot reached the target after a detour around the sofa."},
            "concerns": [{"kind": "close_proximity", "severity": 0.6, "description": "passed within a few cm of "
                          "the sofa corner", "grid_x": 41.0, "grid_y": 55.0, "objects": []},
                         {"kind": "detour", "severity": 0.4, "description": "took the long way around the table",
                          "grid_x": None, "grid_y": None, "objects": []}],
            "suggestions": [{"kind": "narrow_passage", "description": "narrow the gap the robot used between "
                             "the sofa and the wall", "addresses": [1], "priority": 0.9},
                            {"kind": "occlude_target", "description": "hide the target from the approach",
                             "addresses": [], "priority": 0.6}]}


def server_module() -> Any:
    spec = importlib.util.spec_from_file_location("llm_server", ROOT / "tests" / "adapt" / "llm_server.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["llm_server"] = mod
    spec.loader.exec_module(mod)
    return mod


def image_tokens(data_url: str) -> int:
    """gpt-4.1-mini tokens of one PNG data URL (patches of 32 px, capped, times 1.62)."""
    png = base64.b64decode(data_url.split(",", 1)[1])
    w, h = struct.unpack(">II", png[16:24])
    patches = math.ceil(w / 32) * math.ceil(h / 32)
    if patches > PATCH_CAP:  # scaled down to fit the cap, as the guide describes
        scale = math.sqrt(PATCH_CAP * 32 * 32 / (w * h))
        patches = min(PATCH_CAP, math.ceil(w * scale / 32) * math.ceil(h * scale / 32))
    return math.ceil(patches * PATCH_MULTIPLIER)


def text_tokens(text: str) -> int:
    return math.ceil(len(text) / CHARS_PER_TOKEN)


def request_tokens(body: dict[str, Any]) -> int:
    """Estimated input tokens of a Responses API request body."""
    n = text_tokens(body.get("instructions") or "")
    for item in body.get("input") or []:
        content = item.get("content")
        if isinstance(content, str):
            n += text_tokens(content)
            continue
        for part in content or []:
            n += image_tokens(part["image_url"]) if part["type"] == "input_image" else text_tokens(part["text"])
    n += text_tokens(json.dumps(body.get("tools") or [])) + text_tokens(json.dumps(body.get("text") or {}))
    return n


def reply(srv: Any) -> Any:
    """Answer any F or G request and bill it as gpt-4.1-mini would (estimated)."""
    moves = [0]

    def answer(body: dict[str, Any]) -> tuple[int, dict[str, Any]]:
        tokens_in = request_tokens(body)
        tools = body.get("tools") or []
        if not tools:
            text = json.dumps(F_ANSWER)
            return 200, srv.responses_text_reply(text, input_tokens=tokens_in, output_tokens=text_tokens(text))
        if tools[0]["name"] == "propose_move_instruction":
            ids = tools[0]["parameters"]["properties"]["object_id"]["enum"]
            oid = ids[moves[0] % len(ids)]  # a different object each time
            moves[0] += 1
            args = {"object_id": oid, "x_direction": "right", "x_units": 4, "y_direction": "up", "y_units": 3,
                    "rotation": 90}
        else:
            args = {"matches_intent": True, "reason": "The object now narrows the passage as intended.",
                    "revised_move": None}
        return 200, srv.responses_tool_reply(tools[0]["name"], args, input_tokens=tokens_in,
                                             output_tokens=text_tokens(json.dumps(args)) + 10)
    return answer


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--prompts", default="adaptenv", choices=["adaptenv", "paper"])
    ap.add_argument("--house-seed", type=int, default=5)
    args = ap.parse_args()

    from adaptenv.cli import app
    from adaptenv.scene.house import save_house
    from adaptenv.scene.procedural import GenerationConfig, generate_house

    srv = server_module()
    with tempfile.TemporaryDirectory() as tmp:
        house = save_house(generate_house(args.house_seed, GenerationConfig(n_rooms=4)), Path(tmp) / "h.json")
        with srv.ScriptedLLMServer({srv.RESPONSES_PATH: [reply(srv)] * 200}, max_requests=200,
                                   timeout_s=600) as server:
            result = CliRunner().invoke(app, [
                "adapt", str(house), "--analyzer", "llm", "--generator", "llm", "--api", "responses",
                "--base-url", server.url, "--model", "gpt-4.1-mini", "--prompts", args.prompts,
                "--steps", str(args.steps), "--seed", str(args.seed), "--price-in", "0.40", "--price-out", "1.60",
                "-o", str(Path(tmp) / "out")], env={"ADAPTENV_LLM_API_KEY": "not-needed"})
            if result.exit_code not in (0, 1):
                raise SystemExit(result.output + repr(result.exception))
        summary = json.loads((Path(tmp) / "out" / "summary.json").read_text())
    usage = summary["usage"]
    print(f"prompts {args.prompts}, {args.steps} steps, seed {args.seed}, house seed {args.house_seed}: "
          f"{summary['edits_applied']} edits applied")
    for role, u in sorted(usage["by_role"].items()):
        print(f"  {role:6s} calls {u['calls']:2d}  input {u['input_tokens']:7,d}  output {u['output_tokens']:5,d}  "
              f"USD {u['cost_usd']:.5f}")
    print(f"  total  calls {usage['calls']:2d}  input {usage['input_tokens']:7,d}  output {usage['output_tokens']:5,d}  "
          f"USD {usage['cost_usd']:.5f}")


if __name__ == "__main__":
    main()
