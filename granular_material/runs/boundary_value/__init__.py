"""Boundary-value runs: their specification (``spec``), what they need told before they are
made (``checks``), their material (``material``), the run (``runner``), its phases
(``phases``) and its checkpoint (``resume``).
"""
