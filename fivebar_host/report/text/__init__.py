"""Text and file reports (no matplotlib): the dry run, the workspace and design figures, the
linkage files and summaries, the executed path from recorded motor positions."""
