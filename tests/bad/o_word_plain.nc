; O-words @ 2:5
N10 O100
