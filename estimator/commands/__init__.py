"""CLI subcommands that need only the estimator. Each module defines ``NAME``, ``HELP``,
``add_arguments(parser)`` and ``execute(args) -> int``; ``inspector.cli`` assembles them."""
