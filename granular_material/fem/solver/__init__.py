"""Newton–Raphson load stepping (``newton``): its settings, the rules that end an increment
(``convergence``), relaxation and secant updates (``acceleration``), what it hands out
(``records``) and the commands' defaults (``defaults``).
"""
