"""Cross-validation against YADE: identical RVEs and loadings in both engines, compared.

Modules: yade_io (scene export/import), yade_runner (yade -n -x subprocesses),
engine_runner (our DEM in this process, our FEM command line), cases, metrics (acceptance
rules), report, cli (validate-yade). The scripts YADE itself runs are in yade_scripts/.
"""
