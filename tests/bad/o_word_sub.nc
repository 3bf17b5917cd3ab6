; subroutine o200 is not defined @ 2:1
o200 call
