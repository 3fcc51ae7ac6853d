/* The benchmark's floor: a minimal EtherCAT responder on a packet socket.
 * It answers each frame as processed (source MAC bit 1 set, the first datagram's WKC
 * counted) with nothing else, in the daemon's wake-up mode (argv[2] "busy": poll without
 * blocking). Built by ecatsim.bench.floor with the system compiler. Ref: ETG.1000.4 §5.2. */
#include <arpa/inet.h>
#include <linux/if_packet.h>
#include <net/ethernet.h>
#include <net/if.h>
#include <sys/socket.h>
#include <string.h>
#include <stdio.h>
int main(int argc, char **argv) {
    int s = socket(AF_PACKET, SOCK_RAW, htons(0x88A4));
    struct sockaddr_ll a; memset(&a, 0, sizeof a);
    a.sll_family = AF_PACKET; a.sll_protocol = htons(0x88A4);
    a.sll_ifindex = if_nametoindex(argv[1]);
    if (s < 0 || bind(s, (struct sockaddr *)&a, sizeof a) < 0) { perror("echo"); return 1; }
    int busy = argc > 2 && strcmp(argv[2], "busy") == 0;  /* the same wake-up mode */
    unsigned char buf[2048];
    for (;;) {
        ssize_t n = recv(s, buf, sizeof buf, busy ? MSG_DONTWAIT : 0);
        if (n < 30 || (buf[6] & 2)) continue;       /* our own replies come back too */
        buf[6] |= 2;                                 /* processed: source MAC bit 1 */
        unsigned len = (buf[22] | (buf[23] << 8)) & 0x7FF;
        unsigned w = 26 + len;                        /* first datagram's WKC */
        if (w + 2 <= (unsigned)n) buf[w] += 1;
        send(s, buf, n, 0);
    }
}
