; X word with no motion mode @ 3:1
G21
X10
