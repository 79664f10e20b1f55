"""What the vehicle meets: currents and forces, waves, obstacles, sensor noise."""
