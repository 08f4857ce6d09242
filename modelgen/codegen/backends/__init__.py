"""Backends: each output language of the generated filter as one package (``c``, ``python``, ``cpp``).

A backend turns the language-neutral :class:`~modelgen.codegen.description.FilterDescription`
into files: it owns its expression printer, literals, template context,
product templates (``<lang>/templates/``) and the list of files it writes;
templates that only test or drive the product (a C test driver, firmware
main) live apart in ``<lang>/harness/``.  ``registry.backends()`` lists them in the
order their files are rendered; README.md in this folder is the recipe for a new one.
"""
