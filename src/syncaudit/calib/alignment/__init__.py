"""Stage 2, alignment: scans registered (GICP), stop pairs and cross-LiDAR pairs aligned and checked, the coarse turn chain."""
