; is not a valid G code @ 2:1
G[10**300]
