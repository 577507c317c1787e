"""The documentation: every code block runs as written, and every hook, kind and public name is documented."""

import functools
import inspect
import os
import re
from pathlib import Path

import pytest

from flockkit import registry
from flockkit.kinds import KINDS
from flockkit.registry import _protocol_methods

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def blocks(path) -> list[tuple[str, str]]:
    """(language, text) of every fenced code block of a page, in order."""
    return re.findall(r"^```(\w*)\n(.*?)^```", path.read_text(), flags=re.S | re.M)


def python_blocks(path):
    return [text for language, text in blocks(path) if language == "python"]


# How each kind of block is run, exactly as written: Python in one namespace per page; shell lines
# in the page's folder after the Python before them (`flockkit demo` runs in tests/cli, the install
# commands in CI, which .ci/run must run verbatim); TOML parsed. Text blocks are usage synopses,
# outputs, and commands for another machine (a cluster, Blender's console): never run.
RUN = {"python", "bash", "toml"}
INSTALL = re.compile(r"^(python3 -m )?pip install ")


@pytest.mark.parametrize("page", [p for p in PAGES if any(lang in RUN for lang, _ in blocks(p))],
                         ids=lambda p: str(p.relative_to(ROOT)))  # fmt: skip
def test_every_code_block_runs_as_written(page, tmp_path, monkeypatch):
    """Each page's blocks, in order, in a fresh folder that has the shared data beside it, as a
    checkout does (examples that read ../shared/data need it)."""
    import subprocess
    import sys
    import tomllib

    from .conftest import SHARED_DATA, require_folder

    work = tmp_path / "work"
    work.mkdir()
    if "../shared/data" in page.read_text():
        (tmp_path / "shared").symlink_to(require_folder(SHARED_DATA).parent, target_is_directory=True)
    monkeypatch.chdir(work)
    namespace = {"__name__": "docs_example"}
    ci = (ROOT / ".ci" / "run").read_text()
    scripts = Path(sys.executable).parent  # the flockkit command of this environment
    try:
        for language, text in blocks(page):
            if language == "python":
                exec(compile(text, str(page), "exec"), namespace)
            elif language == "toml":
                tomllib.loads(text)
            elif language == "bash":
                for line in (line.strip() for line in text.splitlines()):
                    if not line or line.startswith("#") or line.startswith("flockkit demo"):
                        continue
                    if INSTALL.match(line):
                        command = line.split(" && ")
                        tested = command[-1] == "python3 -m pytest" and " && ".join(command) in ci
                        assert tested or command[-1] in ("flockkit demo", "") or len(command) == 1, line
                        continue
                    done = subprocess.run(line, shell=True, cwd=work, capture_output=True, text=True,
                                          env={**os.environ, "PATH": f"{scripts}:{os.environ['PATH']}"})  # fmt: skip
                    assert done.returncode == 0, f"{page.name}: {line}: {done.stderr[-500:]}"
    finally:
        registry.reset()


def test_text_blocks_hold_no_code_to_run():
    """A block marked text is a synopsis, an output, or a command for another machine; code for
    this one is marked python or bash, and runs."""
    for page in PAGES:
        for language, text in blocks(page):
            if language in ("text", ""):
                first = text.strip().splitlines()[0] if text.strip() else ""
                assert not first.startswith(("import ", "from ", "python3 ", "pip ")) or "bpy" in text, (
                    f"{page.name}: a text block that is code: {first}"
                )


@pytest.mark.parametrize("kind", list(KINDS))
def test_every_kind_has_a_page_stating_its_hook_and_methods(kind):
    page = (ROOT / "docs" / "kinds" / f"{kind}.md").read_text()
    assert KINDS[kind].hook in page and KINDS[kind].protocol.__name__ in page
    for method in _protocol_methods(KINDS[kind].protocol):
        assert f"`{method}(" in page, f"docs/kinds/{kind}.md does not state {method}"
    assert KINDS[kind].hook in (ROOT / "docs" / "plugins.md").read_text()


def test_every_doc_page_is_linked_from_the_index():
    index = (ROOT / "docs" / "index.md").read_text()
    for page in (ROOT / "docs").rglob("*.md"):
        if page.name != "index.md":
            assert str(page.relative_to(ROOT / "docs")) in index, page


def test_mkdocs_builds_the_site_strictly(tmp_path):
    """docs/ is a mkdocs site (mkdocs.yml): every page in the nav, every link and image resolves."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")],
        cwd=root,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "site" / "gallery" / "index.html").exists()
    # attrs value types: a field with a default (here a factory) is not shown as required
    import html
    import re

    page = (tmp_path / "site" / "api" / "flockkit" / "index.html").read_text()
    text = " ".join(html.unescape(re.sub("<[^>]+>", " ", page)).split())
    row = re.search(
        r"channels mapping of str to array_like \(T, N, D\) Named per-agent.*?\(default: none\)\. (\S+)", text
    )
    assert row and row.group(1) == "{}", row and row.group(0)


def _all_text():
    return "\n".join(page.read_text() for page in PAGES)


def test_every_public_name_is_documented():
    """Like datasette's "every hook is documented": each name a user can import is in the docs."""
    import flockkit
    import flockkit.parallel
    import flockkit.rigid
    import flockkit.testing
    import flockkit.validate

    text = _all_text()
    missing = [n for n in flockkit.__all__ if n != "__version__" and not re.search(rf"(`|flockkit\.){n}\b", text)]
    modules = (flockkit.rigid, "rigid"), (flockkit.validate, "validate"), (flockkit.parallel, "parallel")
    for module, prefix in (*modules, (flockkit.testing, "")):
        missing += [f"{prefix}.{n}" for n in module.__all__ if not re.search(rf"(`|{prefix}\.){n}\b", text)]
    assert missing == []


def test_every_builtin_parameter_and_capability_is_documented_on_its_kind_page():
    import inspect

    import attrs

    import flockkit

    missing = []
    for component in registry.describe():
        if component.distribution != "flockkit":
            continue
        page = (ROOT / "docs" / "kinds" / f"{component.kind}.md").read_text()
        missing += [
            f"{component.kind} {component.name}: {p}"
            for p in inspect.signature(component.factory).parameters
            if f"`{p}`" not in page
        ]
    for kind, fields in ((k, d.fields) for k, d in KINDS.items()):
        page = (ROOT / "docs" / "kinds" / f"{kind}.md").read_text()
        missing += [
            f"docs/kinds/{kind}.md: Capabilities.{f}" for f in sorted(fields | {"dims"}) if f"`{f}`" not in page
        ]
    documented = flockkit.Capabilities.__doc__
    missing += [
        f"Capabilities docstring: {f.name}" for f in attrs.fields(flockkit.Capabilities) if f.name not in documented
    ]
    assert missing == []


def _value_types():
    import importlib

    paths = sorted({path for kind in KINDS.values() for path in (*kind.receives, *kind.returns)})
    return [(path, getattr(importlib.import_module(path.rpartition(".")[0]), path.rpartition(".")[2]))
            for path in paths]  # fmt: skip


@pytest.mark.parametrize("path, value_type", _value_types(), ids=lambda v: v if isinstance(v, str) else "")
def test_every_value_a_kind_handles_documents_its_fields(path, value_type):
    """A plugin author reads a value's fields, properties and invariants on the reference pages
    (rendered from these docstrings), never in the source."""
    import attrs

    doc = inspect.getdoc(value_type) or ""
    fields = [f.name for f in attrs.fields(value_type) if not f.name.startswith("_")] if attrs.has(value_type) else []
    assert not [f for f in fields if f not in doc], f"{path}: fields not described in its docstring"
    for name, member in vars(value_type).items():
        if isinstance(member, property | functools.cached_property) and not name.startswith("_"):
            assert inspect.getdoc(member), f"{path}.{name} has no docstring"


@pytest.mark.parametrize("kind", list(KINDS))
def test_every_kind_page_renders_the_values_it_handles(kind):
    page = (ROOT / "docs" / "kinds" / f"{kind}.md").read_text()
    for path in (*KINDS[kind].receives, *KINDS[kind].returns):
        assert f"::: {path}" in page, f"docs/kinds/{kind}.md does not render {path}"


@pytest.mark.parametrize("kind", list(KINDS))
def test_every_kind_page_renders_its_protocol_and_what_the_kit_checks(kind):
    """A plugin author reads the methods to write and every rule the kit will hold them to on the
    kind's page: the protocol and the kit module's checks are rendered from their docstrings, and
    every check says what it checks."""
    import importlib

    page = (ROOT / "docs" / "kinds" / f"{kind}.md").read_text()
    protocol = KINDS[kind].protocol
    assert f"::: {protocol.__module__}.{protocol.__name__}" in page.split("## The protocol")[1].split("##")[0]
    checked = page.split("## What the kit checks")[1].split("## ")[0]
    assert f"::: {KINDS[kind].kit}" in checked and 'filters: ["^check_"]' in checked
    for check in importlib.import_module(KINDS[kind].kit).CHECKS:
        assert check.__name__.startswith("check_") and inspect.getdoc(check), f"{check.__name__} says nothing"


def _validate_table() -> str:
    from flockkit import validate

    rows = ["| function | what it checks | options |", "|---|---|---|"]
    for name in validate.__all__:
        function = getattr(validate, name)
        first = " ".join((inspect.getdoc(function) or "").split("\n\n")[0].split())
        first = first.replace(":func:", "").replace("``", "`")
        options = [
            f"`{p.name}`"
            for p in inspect.signature(function).parameters.values()
            if p.kind is p.KEYWORD_ONLY or p.default is not p.empty
        ]
        rows.append(f"| `{name}` | {first} | {', '.join(options) or '-'} |")
    return "\n".join(rows)


def test_the_validate_catalogue_lists_every_check_and_option():
    page = (ROOT / "docs" / "api" / "core.md").read_text()
    assert _validate_table() in page, "docs/api/core.md: the validate catalogue differs from flockkit.validate"
