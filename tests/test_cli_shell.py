"""The command line is a shell over the library: nothing outside tasks/cli imports it, and the
library (tasks/experiments) that the CLI and the benchmarks share runs without loading it."""
import ast
import json
import pkgutil
import subprocess
import sys
from pathlib import Path

import tasks.experiments

ROOT = Path(__file__).resolve().parents[1]


def cli_imports(path: Path, root: Path = ROOT) -> list[str]:
    """``path:line`` (relative to ``root``) of every import of tasks.cli (any form) in the file."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level:
            names = [node.module or ""] + [f"{node.module}.{alias.name}" for alias in node.names]
        if any(name == "tasks.cli" or name.startswith("tasks.cli.") for name in names):
            found.append(f"{path.relative_to(root)}:{node.lineno}")
    return found


def test_the_check_sees_every_form_of_import(tmp_path):
    source = tmp_path / "probe.py"
    lines = ["import tasks.cli", "from tasks.cli import main", "from tasks import cli", "from tasks.cli.task import x",
             "import tasks.experiments", "from tasks.experiments import jobs", "from tasks.clinic import y"]
    source.write_text("\n".join(lines) + "\n")
    assert cli_imports(source, tmp_path) == [f"probe.py:{k}" for k in (1, 2, 3, 4)]


def test_nothing_outside_the_cli_imports_it():
    files = [p for folder in ("bomi", "sim", "tasks", "benchmarks") for p in sorted((ROOT / folder).rglob("*.py"))
             if (ROOT / "tasks" / "cli") not in p.parents]
    assert any(p.name == "jobs.py" for p in files) and any(p.parent.name == "benchmarks" for p in files)
    assert [hit for p in files for hit in cli_imports(p)] == []


def test_importing_the_library_loads_no_cli_module():
    modules = sorted(info.name for info in pkgutil.walk_packages(tasks.experiments.__path__, "tasks.experiments."))
    assert "tasks.experiments.jobs" in modules and "tasks.experiments.summary" in modules
    code = ("import importlib, json, sys\n"
            f"for name in {modules!r}: importlib.import_module(name)\n"
            "print(json.dumps(sorted(m for m in sys.modules if m == 'tasks.cli' or m.startswith('tasks.cli.'))))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert json.loads(done.stdout) == []
