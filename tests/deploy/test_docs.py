"""docs/deploy.md and deploy/zenoh/ say what the code does."""

from __future__ import annotations

from pathlib import Path

import pytest

from fleetlog.deploy.configs import example_configs
from fleetlog.wire.access import access_matrix

REPO = Path(__file__).resolve().parents[2]


def test_the_access_matrix_in_deploy_md_is_the_tables() -> None:
    text = (REPO / "docs" / "deploy.md").read_text()
    start = text.index("<!-- access-matrix")
    start = text.index("\n", start) + 1
    end = text.index("<!-- /access-matrix -->")
    assert text[start:end].strip() == access_matrix(), (
        "regenerate the table: python -c 'from fleetlog.wire.access import access_matrix;"
        " print(access_matrix())'"
    )


@pytest.mark.parametrize("name", sorted(example_configs()))
def test_the_shipped_example_configurations_are_what_deploy_writes(name: str) -> None:
    shipped = (REPO / "deploy" / "zenoh" / name).read_text()
    assert shipped == example_configs()[name], f"regenerate deploy/zenoh/{name}"


def test_docs_have_no_placeholders() -> None:
    text = (REPO / "docs" / "deploy.md").read_text()
    assert "RESULTS" not in text


@pytest.mark.parametrize("name", sorted(example_configs()))
def test_the_shipped_examples_load_in_zenoh(name: str) -> None:
    import zenoh

    zenoh.Config.from_json5((REPO / "deploy" / "zenoh" / name).read_text())
