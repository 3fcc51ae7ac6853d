/* A small SOEM master in redundant mode for tests/integration/test_segments.py.
 *
 *   red_master NIC0 NIC1
 *
 * Opens both NICs with ec_init_redundant, scans, maps, brings every slave to OP and prints
 * "ready SLAVES EXPECTED_WKC". Then reads commands from stdin, one per line:
 *   cycles N   N process-data cycles at 1 ms; prints "cycles N bad B late L op O" (B:
 *              cycles whose reply came with another WKC than the expected one, L: cycles
 *              with no reply within SOEM's frame timeout EC_TIMEOUTRET, O: 1 if every
 *              slave reads OP after)
 *   quit
 * Built with SOEM's sources from pysoem's source distribution (tests/support/soem_build.py).
 */
#include <stdio.h>
#include <string.h>
#include <inttypes.h>

#include "ethercat.h"

static char iomap[4096];

static int all_op(void)
{
   ec_readstate();
   for (int i = 1; i <= ec_slavecount; i++)
      if ((ec_slave[i].state & 0x0F) != EC_STATE_OPERATIONAL)
         return 0;
   return 1;
}

int main(int argc, char *argv[])
{
   if (argc != 3) {
      fprintf(stderr, "usage: red_master NIC0 NIC1\n");
      return 2;
   }
   if (ec_init_redundant(argv[1], argv[2]) <= 0) {
      printf("error init\n");
      return 1;
   }
   int n = ec_config_init(FALSE);
   if (n <= 0) {
      printf("error scan\n");
      return 1;
   }
   ec_config_map(&iomap);
   ec_statecheck(0, EC_STATE_SAFE_OP, EC_TIMEOUTSTATE * 4);
   int expected = ec_group[0].outputsWKC * 2 + ec_group[0].inputsWKC;
   ec_slave[0].state = EC_STATE_OPERATIONAL;
   ec_send_processdata();
   ec_receive_processdata(EC_TIMEOUTRET);
   ec_writestate(0);
   for (int k = 0; k < 200 && ec_slave[0].state != EC_STATE_OPERATIONAL; k++) {
      ec_send_processdata();
      ec_receive_processdata(EC_TIMEOUTRET);
      ec_statecheck(0, EC_STATE_OPERATIONAL, 5000);
   }
   if (!all_op()) {
      printf("error op\n");
      return 1;
   }
   printf("ready %d %d\n", n, expected);
   fflush(stdout);
   char line[64];
   while (fgets(line, sizeof line, stdin)) {
      int cycles = 0;
      if (sscanf(line, "cycles %d", &cycles) == 1) {
         int bad = 0, late = 0;
         for (int i = 0; i < cycles; i++) {
            ec_send_processdata();
            int wkc = ec_receive_processdata(EC_TIMEOUTRET);
            if (wkc <= 0)
               late++;
            else if (wkc != expected)
               bad++;
            osal_usleep(1000);
         }
         printf("cycles %d bad %d late %d op %d\n", cycles, bad, late, all_op());
         fflush(stdout);
      } else if (strncmp(line, "quit", 4) == 0) {
         break;
      }
   }
   ec_slave[0].state = EC_STATE_INIT;
   ec_writestate(0);
   ec_close();
   return 0;
}
