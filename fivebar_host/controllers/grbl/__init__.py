"""A stock GRBL 1.1 board driven in joint space (`--controller grbl`): link, program,
resume, run."""
