"""Build step (mkdocs-gen-files): the command reference page, from the argparse parsers."""

import sys
from pathlib import Path

import mkdocs_gen_files

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # this checkout's facebasis and problems

from facebasis.cli import build_parser
from facebasis.cli.examples import reference_markdown

with mkdocs_gen_files.open("cli.md", "w") as fh:
    fh.write(reference_markdown(build_parser()))
mkdocs_gen_files.set_edit_path("cli.md", "../facebasis/cli/examples.py")
