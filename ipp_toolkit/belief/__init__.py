"""What a UAV believes: occupancy maps (fusion, entropy, metrics), the expected gain of a
reading from each waypoint, the neighbourhood prior of interest, and the tables and box sums
that keep them cheap."""
