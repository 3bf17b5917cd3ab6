; named parameter #<depth> is not defined @ 6:4
o1 sub
#<depth> = 2
o1 endsub
o1 call
G0 Z#<depth>
