/* One frame from a RawLink socket by recvmsg(2), shared by the compiled paths
 * (ecatsim/_serve.c: the responder). RawLink.recv_into (ecatsim/link/raw.py) is the
 * reference; tests/unit/link/test_links.py runs both.
 *
 * raw_recv(fd, buf, cap, flags, &stamp) -> frame length in buf (an 802.1Q tag the kernel
 *   moved into PACKET_AUXDATA put back at offset 12); 0 if no frame is waiting (EAGAIN,
 *   EINTR, ENETDOWN); -errno on another error. *stamp: the SO_TIMESTAMPNS receive time
 *   (CLOCK_REALTIME ns), 0 if none. Our own outgoing packets (PACKET_OUTGOING) are skipped.
 *
 * Ref: packet(7) (sll_pkttype, PACKET_AUXDATA), socket(7) (SO_TIMESTAMPNS); IEEE 802.1Q.
 */
#ifndef ECATSIM_RAWIO_H
#define ECATSIM_RAWIO_H
#include <errno.h>
#include <linux/if_packet.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>

#define ETH_P_8021Q 0x8100

static long raw_recv(int fd, unsigned char *buf, long cap, int flags, long long *stamp)
{
    for (;;) {
        struct sockaddr_ll addr;
        union {
            struct cmsghdr align;
            char data[CMSG_SPACE(sizeof(struct tpacket_auxdata)) +
                      CMSG_SPACE(sizeof(struct timespec)) + 64];
        } control;
        struct iovec iov = {buf, (size_t)cap};
        struct msghdr msg;
        memset(&msg, 0, sizeof msg);
        msg.msg_name = &addr;
        msg.msg_namelen = sizeof addr;
        msg.msg_iov = &iov;
        msg.msg_iovlen = 1;
        msg.msg_control = control.data;
        msg.msg_controllen = sizeof control.data;
        ssize_t got = recvmsg(fd, &msg, flags);
        *stamp = 0;
        if (got < 0) {
            int e = errno;
            if (e == EAGAIN || e == EWOULDBLOCK || e == EINTR || e == ENETDOWN)
                return 0;
            return -e;
        }
        if (msg.msg_namelen >= sizeof addr - sizeof addr.sll_addr &&
            addr.sll_pkttype == PACKET_OUTGOING)
            continue;
        long n = (long)got;
        for (struct cmsghdr *c = CMSG_FIRSTHDR(&msg); c != NULL; c = CMSG_NXTHDR(&msg, c)) {
            if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_TIMESTAMPNS &&
                c->cmsg_len >= CMSG_LEN(sizeof(struct timespec))) {
                struct timespec ts;
                memcpy(&ts, CMSG_DATA(c), sizeof ts);
                *stamp = (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
            } else if (c->cmsg_level == SOL_PACKET && c->cmsg_type == PACKET_AUXDATA &&
                       c->cmsg_len >= CMSG_LEN(sizeof(struct tpacket_auxdata))) {
                struct tpacket_auxdata aux;
                memcpy(&aux, CMSG_DATA(c), sizeof aux);
                if ((aux.tp_status & TP_STATUS_VLAN_VALID) && n >= 12 && n + 4 <= cap) {
                    unsigned tpid = (aux.tp_status & TP_STATUS_VLAN_TPID_VALID)
                                        ? aux.tp_vlan_tpid
                                        : ETH_P_8021Q;
                    memmove(buf + 16, buf + 12, (size_t)(n - 12));
                    buf[12] = (unsigned char)(tpid >> 8);
                    buf[13] = (unsigned char)tpid;
                    buf[14] = (unsigned char)(aux.tp_vlan_tci >> 8);
                    buf[15] = (unsigned char)aux.tp_vlan_tci;
                    n += 4;
                }
            }
        }
        return n;
    }
}

#endif
