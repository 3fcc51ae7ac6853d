/*
 * eoe_bridge: a small SOEM master that bridges a TAP device to one slave's EoE
 * (ETG.1000.6 section 5.7) while the process data runs, for ecatsim's tests.
 *
 * Usage: eoe_bridge IFNAME SLAVE TAPNAME
 *   IFNAME   the EtherCAT interface, SLAVE the slave number (1 = first),
 *   TAPNAME  the master-side TAP device created here (the test gives it an address).
 *
 * It brings every slave to OP, runs the process data every 2 ms counting cycles whose
 * working counter is not the expected one, and bridges: frames the kernel sends into
 * the TAP device go to the slave with ecx_EOEsend; EoE fragments read from the slave's
 * mailbox are reassembled with ecx_EOEreadfragment (in the EoE hook) and written to the
 * TAP device. Commands on stdin, one per line, each answered with one line on stdout:
 *   setip A.B.C.D/LEN  -> "setip WKC"            (EoE Set IP Parameter)
 *   getip              -> "getip WKC A.B.C.D M.M.M.M"   (EoE Get IP Parameter)
 *   stats              -> "stats cycles=N mismatch=N noframe=N expected=N to_slave=N
 *                          to_master=N send_failed=N rx_broken=N" (mismatch: a reply with
 *                          another working counter; noframe: no reply within the receive
 *                          timeout; send_failed: ecx_EOEsend attempts that failed, each
 *                          retried up to 3 times; rx_broken: fragments out of sequence)
 *   quit
 * "ready expected=N slaves=N" is printed once the slaves are in OP.
 * Written for this project against the SOEM 1.4 API that pysoem's sdist carries.
 */

#include <errno.h>
#include <fcntl.h>
#include <linux/if.h>
#include <linux/if_tun.h>
#include <poll.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include "ethercat.h"

static char iomap[4096];
static int tapfd = -1;
static int eoe_slave = 1;
static int expected_wkc;
static volatile int running = 1;
static volatile long cycles, mismatches, noframes, to_slave, to_master, send_failed, rx_broken;

/* a command for the mailbox thread, which owns the mailbox */
static pthread_mutex_t cmd_lock = PTHREAD_MUTEX_INITIALIZER;
static pthread_cond_t cmd_done = PTHREAD_COND_INITIALIZER;
static char cmd[128];
static int cmd_pending;

/* the reassembly state of ecx_EOEreadfragment */
static uint8 rx_fragment;
static uint16 rx_size, rx_offset, rx_frame;
static uint8 rx_buf[2048];

static int open_tap(const char *name)
{
   struct ifreq ifr;
   int fd = open("/dev/net/tun", O_RDWR | O_NONBLOCK);
   if (fd < 0)
      return -1;
   memset(&ifr, 0, sizeof(ifr));
   ifr.ifr_flags = IFF_TAP | IFF_NO_PI;
   strncpy(ifr.ifr_name, name, IFNAMSIZ - 1);
   if (ioctl(fd, TUNSETIFF, &ifr) < 0)
   {
      close(fd);
      return -1;
   }
   return fd;
}

static int eoe_hook(ecx_contextt *context, uint16 slave, void *eoembx)
{
   int size = sizeof(rx_buf);
   (void)context;
   (void)slave;
   /* only fragments are the hook's: a Set/Get IP response goes back to its caller */
   if (EOE_HDR_FRAME_TYPE_GET(etohs(((ec_EOEt *)eoembx)->frameinfo1)) != EOE_FRAG_DATA)
      return 0;
   int r = ecx_EOEreadfragment(eoembx, &rx_fragment, &rx_size, &rx_offset, &rx_frame,
                               &size, rx_buf);
   if (r > 0)
   {
      if (write(tapfd, rx_buf, size) == size)
         to_master++;
   }
   else if (r < 0)
      rx_broken++; /* a fragment out of sequence: the frame it belonged to is lost */
   return 1;
}

static void *process_data(void *arg)
{
   (void)arg;
   while (running)
   {
      ec_send_processdata();
      int wkc = ec_receive_processdata(EC_TIMEOUTRET);
      cycles++;
      if (wkc <= 0)
         noframes++; /* no reply in time: counted apart from a wrong working counter */
      else if (wkc != expected_wkc)
         mismatches++;
      osal_usleep(2000);
   }
   return NULL;
}

static void run_command(char *line, char *out, size_t n)
{
   int a, b, c, d, len, wkc;
   eoe_param_t p;
   memset(&p, 0, sizeof(p));
   if (sscanf(line, "setip %d.%d.%d.%d/%d", &a, &b, &c, &d, &len) == 5)
   {
      uint32 mask = len ? 0xFFFFFFFFu << (32 - len) : 0;
      p.ip_set = 1;
      p.subnet_set = 1;
      EOE_IP4_ADDR_TO_U32(&p.ip, a, b, c, d);
      EOE_IP4_ADDR_TO_U32(&p.subnet, mask >> 24, mask >> 16, mask >> 8, mask);
      /* a master retries a mailbox request that got no answer in its timeout */
      for (int tries = 0; tries < 3; tries++)
      {
         wkc = ecx_EOEsetIp(&ecx_context, eoe_slave, 0, &p, EC_TIMEOUTRXM);
         if (wkc == 1)
            break;
      }
      if (wkc == 1)
         snprintf(out, n, "setip %d\n", wkc);
      else /* what the mailbox looked like afterwards, for the test's message */
      {
         uint8 sm0 = 0, sm1 = 0;
         uint16 adr = ec_slave[eoe_slave].configadr;
         ecx_FPRD(ecx_context.port, adr, ECT_REG_SM0STAT, 1, &sm0, EC_TIMEOUTRET3);
         ecx_FPRD(ecx_context.port, adr, ECT_REG_SM1STAT, 1, &sm1, EC_TIMEOUTRET3);
         snprintf(out, n, "setip %d sm0=0x%02x sm1=0x%02x\n", wkc, sm0, sm1);
      }
   }
   else if (strncmp(line, "getip", 5) == 0)
   {
      wkc = ecx_EOEgetIp(&ecx_context, eoe_slave, 0, &p, EC_TIMEOUTRXM);
      snprintf(out, n, "getip %d %d.%d.%d.%d %d.%d.%d.%d\n", wkc,
               eoe_ip4_addr1(&p.ip), eoe_ip4_addr2(&p.ip), eoe_ip4_addr3(&p.ip),
               eoe_ip4_addr4(&p.ip), eoe_ip4_addr1(&p.subnet), eoe_ip4_addr2(&p.subnet),
               eoe_ip4_addr3(&p.subnet), eoe_ip4_addr4(&p.subnet));
   }
   else
   {
      snprintf(out, n, "error unknown command\n");
   }
}

static void *mailbox(void *arg)
{
   ec_mbxbuft in;
   uint8 frame[2048];
   char out[160];
   (void)arg;
   while (running)
   {
      int busy = 0;
      pthread_mutex_lock(&cmd_lock);
      if (cmd_pending)
      {
         run_command(cmd, out, sizeof(out));
         fputs(out, stdout);
         fflush(stdout);
         cmd_pending = 0;
         pthread_cond_signal(&cmd_done);
      }
      pthread_mutex_unlock(&cmd_lock);
      for (int i = 0; i < 4; i++)
      {
         ssize_t n = read(tapfd, frame, sizeof(frame));
         if (n <= 0)
            break;
         /* a frame whose mailbox write got no answer in time is sent again, as a master's
            retry; each failed attempt is counted */
         for (int tries = 0; tries < 3; tries++)
         {
            if (ecx_EOEsend(&ecx_context, eoe_slave, 0, (int)n, frame, EC_TIMEOUTRXM) > 0)
            {
               to_slave++;
               break;
            }
            send_failed++;
         }
         busy = 1;
      }
      ec_clearmbx(&in);
      /* EoE fragments are taken by the hook; anything else is reported */
      int wkc = ecx_mbxreceive(&ecx_context, eoe_slave, &in, 0);
      if (wkc > 0)
         fprintf(stderr, "unexpected mailbox type 0x%x\n", ((ec_mbxheadert *)in)->mbxtype);
      if (!busy)
      {
         struct pollfd pfd = {tapfd, POLLIN, 0};
         poll(&pfd, 1, 1);
      }
   }
   return NULL;
}

int main(int argc, char *argv[])
{
   pthread_t pd, mb;
   char line[128];
   if (argc < 4)
   {
      fprintf(stderr, "usage: eoe_bridge IFNAME SLAVE TAPNAME\n");
      return 2;
   }
   eoe_slave = atoi(argv[2]);
   setvbuf(stdout, NULL, _IOLBF, 0);
   tapfd = open_tap(argv[3]);
   if (tapfd < 0)
   {
      fprintf(stderr, "cannot create TAP %s: %s\n", argv[3], strerror(errno));
      return 1;
   }
   if (!ec_init(argv[1]))
   {
      fprintf(stderr, "ec_init on %s failed\n", argv[1]);
      return 1;
   }
   if (ec_config_init(FALSE) < eoe_slave)
   {
      fprintf(stderr, "slave %d not found\n", eoe_slave);
      return 1;
   }
   ecx_EOEdefinehook(&ecx_context, eoe_hook);
   ec_config_map(&iomap);
   ec_statecheck(0, EC_STATE_SAFE_OP, EC_TIMEOUTSTATE * 4);
   expected_wkc = (ec_group[0].outputsWKC * 2) + ec_group[0].inputsWKC;
   ec_slave[0].state = EC_STATE_OPERATIONAL;
   ec_send_processdata();
   ec_receive_processdata(EC_TIMEOUTRET);
   ec_writestate(0);
   for (int chk = 200; chk > 0 && ec_slave[0].state != EC_STATE_OPERATIONAL; chk--)
   {
      ec_send_processdata();
      ec_receive_processdata(EC_TIMEOUTRET);
      ec_statecheck(0, EC_STATE_OPERATIONAL, 50000);
   }
   if (ec_slave[0].state != EC_STATE_OPERATIONAL)
   {
      fprintf(stderr, "not all slaves reached OP\n");
      return 1;
   }
   pthread_create(&pd, NULL, process_data, NULL);
   pthread_create(&mb, NULL, mailbox, NULL);
   printf("ready expected=%d slaves=%d\n", expected_wkc, ec_slavecount);
   while (fgets(line, sizeof(line), stdin))
   {
      if (strncmp(line, "quit", 4) == 0)
         break;
      if (strncmp(line, "stats", 5) == 0)
      {
         printf("stats cycles=%ld mismatch=%ld noframe=%ld expected=%d to_slave=%ld "
                "to_master=%ld send_failed=%ld rx_broken=%ld\n", cycles, mismatches, noframes,
                expected_wkc, to_slave, to_master, send_failed, rx_broken);
         continue;
      }
      pthread_mutex_lock(&cmd_lock);
      strncpy(cmd, line, sizeof(cmd) - 1);
      cmd_pending = 1;
      while (cmd_pending)
         pthread_cond_wait(&cmd_done, &cmd_lock);
      pthread_mutex_unlock(&cmd_lock);
   }
   running = 0;
   pthread_join(mb, NULL);
   pthread_join(pd, NULL);
   ec_slave[0].state = EC_STATE_INIT;
   ec_writestate(0);
   ec_close();
   return 0;
}
