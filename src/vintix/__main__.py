"""``python -m vintix``: the same command line as the installed ``vintix`` script."""

from vintix.cli import app

# prog_name keeps usage lines reading "vintix ..." rather than "__main__.py ...".
app(prog_name="vintix")
