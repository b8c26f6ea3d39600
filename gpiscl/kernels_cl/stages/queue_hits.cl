/* From: ray queue `in` with final hits.  To: ray indices split into the hit queue
 * (surfaces and GPIS events) and the escaped queue. */
__kernel void queue_hits(QUEUE_HITS_PARAMS)
{
    int i = get_global_id(0);
    if (i >= num_rays) return;
    if (in_hit_prim[i] != -1) hits_ray[atomic_inc(&counters[COUNT_HITS])] = i;
    else escaped_ray[atomic_inc(&counters[COUNT_ESCAPED])] = i;
}
