"""The materials: the protocol the Newton driver and scikit-fem scripts talk to (``protocol``),
what a material answers (``response``) and is told of its run (``run_context``), the checks
every material makes of its input (``checks``), and the continuum materials: linear
elasticity and Mohr–Coulomb (its parameters and return mapping beside it); ``regions``, one
material per region of the mesh answering as one.
"""
