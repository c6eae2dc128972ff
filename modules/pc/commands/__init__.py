"""The robot's ``tokenring`` verbs, added through :mod:`modules.plugin`: each module has
``add_parser(sub)`` and ``run(args)``, like :mod:`tokenring.cli.commands`."""
