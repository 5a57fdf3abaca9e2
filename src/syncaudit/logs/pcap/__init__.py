"""pcap / pcapng network captures of LiDAR traffic, read as logs of sensor streams."""
