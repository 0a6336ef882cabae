"""One module per ``ehpss-hil`` subcommand (discovered by ``ehpss_hil.cli``)."""
