"""Build step (mkdocs-gen-files): the command reference page, from the argparse parsers."""

import mkdocs_gen_files

from facebasis.cli.examples import reference_markdown

with mkdocs_gen_files.open("cli.md", "w") as fh:
    fh.write(reference_markdown())
mkdocs_gen_files.set_edit_path("cli.md", "../facebasis/cli/examples.py")
