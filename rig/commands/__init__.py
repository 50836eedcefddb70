"""One module per `rig` subcommand; each exposes ``add_parser(subparsers)``."""
