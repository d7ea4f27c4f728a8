"""Learning methods written as a user would write one, to copy (shipped with the package).

`learn.examples.toy_method`: a whole method in one file (config, trainer, policy,
loader, registration), imported with ``--method-module learn.examples.toy_method`` (or
the path of a copy: ``--method-module my_method.py``). Importing a module here registers
its method; nothing here is imported by `learn` itself.
"""
