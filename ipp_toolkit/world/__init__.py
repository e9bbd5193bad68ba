"""The world a mission flies over: ground-truth terrains and their families, the downward
camera and its noise, and the random streams every mission draws from."""
