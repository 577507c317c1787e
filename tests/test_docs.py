"""The documentation: every Python example runs, and every hook and kind is documented."""

import re
from pathlib import Path

import pytest

from flockkit import registry
from flockkit.kinds import KINDS
from flockkit.registry import _protocol_methods

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def python_blocks(path):
    return re.findall(r"```python\n(.*?)```", path.read_text(), flags=re.S)


@pytest.mark.parametrize("page", [p for p in PAGES if python_blocks(p)], ids=lambda p: str(p.relative_to(ROOT)))
def test_examples_run(page, tmp_path, monkeypatch):
    """Each page's examples, run in a fresh folder that has the shared data beside it, as a
    checkout does (examples that read ../shared/data need it)."""
    from .conftest import SHARED_DATA, require_folder

    work = tmp_path / "work"
    work.mkdir()
    if "../shared/data" in page.read_text():
        (tmp_path / "shared").symlink_to(require_folder(SHARED_DATA).parent, target_is_directory=True)
    monkeypatch.chdir(work)
    namespace = {"__name__": "docs_example"}
    try:
        for block in python_blocks(page):  # blocks of one page share a namespace, as a reader's session would
            exec(compile(block, str(page), "exec"), namespace)
    finally:
        registry.reset()


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
