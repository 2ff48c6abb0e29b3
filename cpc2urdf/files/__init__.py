"""The core file formats: JSON I/O, robot specs, model files, measurements (JSON, tracker and FIGAROH
CSV), poses and units at the file boundary, and the one resolver of "which robot"."""
