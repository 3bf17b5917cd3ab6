; #<dpeth> is not defined @ 3:9
#<depth> = 2
G1 F100 Z[#<dpeth>]
