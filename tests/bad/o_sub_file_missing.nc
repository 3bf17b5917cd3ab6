; subroutine o<nosuchfile> is not defined (and no file nosuchfile.ngc was found) @ 2:1
o<nosuchfile> call [1]
