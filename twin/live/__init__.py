"""The live twin: a Kalman observer on the ROM beside a running machine, over OPC UA (``twin live``)."""
