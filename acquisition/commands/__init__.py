"""Subcommands of ``imu-square`` that talk to hardware: registered by entry point."""
