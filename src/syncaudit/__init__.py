"""syncaudit: audit LiDAR-camera synchronisation and LiDAR extrinsics in recorded drive logs."""

__version__ = "0.1.0"
