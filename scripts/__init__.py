"""Command-line entry points (thin: parse, call into agent/ envs/ knowledge/, print)."""
