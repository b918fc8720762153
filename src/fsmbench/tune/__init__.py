"""``fsmbench tune``: identify with the loop closed, design, load only what is better."""
