"""What the README, the docs site and the command line say of each other agrees."""

from __future__ import annotations

import re
from pathlib import Path

import yaml
from cli_run import run

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text()


def test_readme_lists_every_builtin_name_the_commands_accept():
    # the demo and older scripts use aliases (platform-3dof): the README's table names them
    from airbearing.io.builtins import builtin_names

    rows = re.findall(r"^\| `([a-z0-9-]+)` \| (?:platform|cmg) \|", README, re.M)
    assert sorted(rows) == sorted(builtin_names(aliases=True))


def test_readme_links_every_tutorial():
    for page in sorted((ROOT / "docs" / "tutorials").glob("*.md")):
        assert f"(docs/tutorials/{page.name})" in README, page.name


def test_identify_says_the_same_in_the_readme_and_in_help(capsys):
    row = next(line for line in README.splitlines() if line.startswith("| `airbearing identify"))
    assert "CM offset" in row
    assert run(["--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    listed = text[text.index("identify ") : text.index(" simulate ")]
    assert "CM offset" in listed, listed


def test_site_opened_as_files_links_pages_not_folders():
    class Loader(yaml.SafeLoader):
        pass

    # mkdocs.yml may carry !!python/name tags of extensions: read them as plain text
    Loader.add_multi_constructor("", lambda loader, suffix, node: None)
    config = yaml.load((ROOT / "mkdocs.yml").read_text(), Loader=Loader)
    assert config.get("use_directory_urls") is False


def test_testbed_list_fits_a_terminal(capsys):
    from airbearing.cli.testbed import LIST_WIDTH

    assert run(["testbed", "list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert max(len(line) for line in lines) <= LIST_WIDTH
    assert any(line.startswith("platform-3dof") and "seed000-tabletop" in line for line in lines)


def test_a_log_check_plots_without_its_log_again():
    # docs/how-to/python.md: `check.plot()` (the result keeps the log it checked)
    import matplotlib

    matplotlib.use("Agg")
    import airbearing as ab

    run_ = ab.spindown(ab.load_testbed("cmg-yaw"), initial_rate=1.0, duration=2.0)
    check = ab.check_log(run_.log)
    fig = check.plot()
    assert fig.axes
    assert "checked" not in check.to_json() and "checked" not in repr(check)
    assert "check.plot()" in (ROOT / "docs" / "how-to" / "python.md").read_text()
