"""Line-us drawing robot: protocol, client, simulator, drawing pipeline and CLI."""
