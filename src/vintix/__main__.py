"""``python -m vintix``: the same command line as the installed ``vintix`` script (and the one each
process of ``torchrun --nproc-per-node N -m vintix train ...`` runs)."""

from vintix.cli import app

# prog_name keeps usage lines reading "vintix ..." rather than "__main__.py ...".
app(prog_name="vintix")
