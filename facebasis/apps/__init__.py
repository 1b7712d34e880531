"""Applications built on the whole package, beside the command line (they sit on top of every
method sub-package and nothing in the library imports them).

Modules
-------
demo            ``facebasis demo``: the main job on the built-in face, end to end
"""
