"""CLI subcommands that need the inspector (viser)."""
