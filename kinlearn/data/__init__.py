"""What the robot experiences: motor babbling and endpoint pairs."""
