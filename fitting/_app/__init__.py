"""fitting's application layer: its main-job parts and its subcommands (registered with pmpjax's
command line through entry points)."""
