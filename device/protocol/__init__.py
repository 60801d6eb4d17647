"""The OpenShoe / MIMU / Oblu protocol: the framer, the host commands, one codec per output mode."""
