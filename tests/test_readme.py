"""The README's Python examples run as written (documentation that cannot drift)."""

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_blocks_run():
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    runnable = [b for b in blocks if "PORT" not in b]  # the serve example needs a live service
    assert len(runnable) >= 2
    namespace: dict = {}
    for block in runnable:
        exec(compile(block, str(README), "exec"), namespace)
    # the claims written next to the code
    w, q = namespace["w"], namespace["q"]
    assert w[:, 1].max() > 0.99 and w[:, 1].min() < -0.99          # the flip happens
    assert abs(abs(q[-1] @ q[-1]) - 1.0) < 1e-14
    assert namespace["R"].shape == (1000, 3)
