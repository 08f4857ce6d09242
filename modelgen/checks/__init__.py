"""The checks: evidence that a derived model and its generated code are right.

``paper_check`` compares a derived model entry by entry with the paper's
table (``paper_table`` reads it); ``code_check`` runs the generated Python
and C filters step by step against the numpy reference filter;
``embedded_check`` builds the single-precision C for a Cortex-M4 and runs it
under qemu; ``crosscheck`` compares each hand-written model with its twin
derived from the navigation equations, ``paper_equations`` the paper's
printed equations with that derivation (``twins`` runs both for a run).  They use the derive layer and the code generator and are called
by the jobs (``modelgen.jobs``) and the command line.
"""
