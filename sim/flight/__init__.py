"""What flies the vehicle, after PX4's commander and navigator: arming, modes, failsafes, RTL
and mission blocks, the land detector, stick input."""
