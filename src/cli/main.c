#include "run.h"

int main(int argc, char **argv)
{
    return ef_main(argc, argv);
}
